"""The physics of a compiled line, one module per family of elements.

:func:`r2rsim.compile.kernels.evaluate` calls the phases below in this order; each phase is a
compiled function over its family's records (views of the flat arrays ``I`` and ``P``) and
the intermediates of the earlier phases (views of the scratch array ``W``):

======  =========================================  ==========================================
phase   function                                   computes
======  =========================================  ==========================================
-       :func:`.faults.fault_profiles`             fault profiles into their parameters
0       :func:`.spans.fixed_lengths`               span lengths and E·A
0       :func:`.movers.mover_spans`                lengths of the spans a mover carries
0       :func:`.rolls.eccentric_lengths`           an eccentric roller's share of them
0       :func:`.joints.joint_compliance`           splice joints' compliance
1       :func:`.spans.span_tensions`               span tensions
2       :func:`.rolls.roll_geometry`               radius, inertia, angular speed
2b      :func:`.movers.mover_dynamics`             a mover's equation of motion
3       :func:`.sensors.sensor_readings`           readings, sensor faults
4       :func:`.controllers.tension_loops`         tension and dancer loops
5       :func:`.controllers.torque_commands`       speed loops, torque-mode control
6       :func:`.drives.drive_torques`              drive saturation and torque lag
7       :func:`.rolls.surface_speeds`              surface speeds
8       :func:`.sensors.imposed_speed_encoders`    encoders on imposed-speed nodes
9       :func:`.rolls.torque_balance`              J(R)·dω/dt
10      :func:`.rolls.roll_lengths`                a roll's lengths s and u
11      :func:`.spans.span_balance`                mass conservation de/dt
12      :func:`.sensors.sensor_filters`            sensor filters
13      :func:`.outputs.outputs`                   algebraic outputs (when recorded)
======  =========================================  ==========================================

:mod:`.events` holds the event functions, :mod:`.programme` the set-points and disturbance
tables, :mod:`.transport` the flux of web through a node, and :mod:`.base` what they share
(the ``kernel`` decorator, views, gradient helpers). ``docs/model.md`` explains how to add a
phase or an element kind.
"""
