"""Stand-ins for a sweep worker's task (importable by spawned worker processes): a run that
kills its own worker, as the out-of-memory killer would, and runs that finish."""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class Spec:
    run_id: str


def die_on_oom(spec: Spec, work: str) -> dict:
    """Finish (after a short while, so other runs are in flight), unless the run id starts
    with 'oom': then the worker is killed."""
    time.sleep(0.3)
    if spec.run_id.startswith("oom"):
        os.kill(os.getpid(), signal.SIGKILL)
    return {"run_id": spec.run_id, "status": "done", "pid": os.getpid()}
