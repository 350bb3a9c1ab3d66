"""Web material presets (machine direction), from physics.md §2.1.

Values are typical mid-range numbers; every one can be overridden in the line file.
"""

from __future__ import annotations

#: name -> properties in SI (modulus Pa, density kg/m^3, break_stress Pa)
MATERIALS: dict[str, dict[str, float]] = {
    # BOPET: E 4-5 GPa, rho 1390 kg/m^3, tensile >= 210 MPa MD (physics.md 2.1, Line A)
    "PET": {"modulus": 4.5e9, "density": 1390.0, "break_stress": 210e6},
    # newsprint / light paper: E 3-7 GPa, rho 600-750 kg/m^3; Line B uses 5 GPa, 650 kg/m^3,
    # ~1.8 kN/m breaking load at 65 um -> ~27 MPa
    "paper": {"modulus": 5.0e9, "density": 650.0, "break_stress": 27e6},
    # aluminium foil: E 69-70 GPa, rho 2700; Line C: 100 MPa break (annealed 60-100 MPa)
    "aluminium": {"modulus": 69e9, "density": 2700.0, "break_stress": 100e6},
    # copper foil (anode collector): E 110-130 GPa, rho 8960, 200-400 MPa
    "copper": {"modulus": 110e9, "density": 8960.0, "break_stress": 200e6},
}
MATERIALS["aluminum"] = MATERIALS["aluminium"]
