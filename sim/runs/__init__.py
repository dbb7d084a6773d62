"""RUN FILES: read, write and validate (``runfile``), build one from a loop result (``build``), and the atomic output writers (``files``)."""

from sim.runs.build import build_runfile
from sim.runs.files import out_dir, write_json_atomic, write_text_atomic
from sim.runs.runfile import CHANNELS, FORMAT, RunFile, read_run, write_run

__all__ = [
    "CHANNELS",
    "FORMAT",
    "RunFile",
    "build_runfile",
    "out_dir",
    "read_run",
    "write_json_atomic",
    "write_run",
    "write_text_atomic",
]
