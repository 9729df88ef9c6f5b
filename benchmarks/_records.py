"""What a benchmark's results file records beside its figures: the command, the commit, the machine
and its load, and the summary figures of a sample (``figures``)."""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def figures(x) -> dict:
    """Mean, median, p90, max, min and count of a sample (in its own unit)."""
    x = np.asarray(x, dtype=float)
    return {"mean": float(x.mean()), "median": float(np.median(x)), "p90": float(np.percentile(x, 90)),
            "max": float(x.max()), "min": float(x.min()), "n": int(x.size)}


def run_record(command: str, load_start, load_end) -> dict:
    """The command, the commit (short hash), the date, the machine's cores, CPU and Python, and the
    load average at the start and end of the run."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=REPO).stdout.strip()
    return {"command": command, "commit": commit, "date": datetime.date.today().isoformat(),
            "cores": os.cpu_count(), "cpu": platform.processor() or platform.machine(),
            "python": platform.python_version(), "load_average_start": list(load_start),
            "load_average_end": list(load_end)}
