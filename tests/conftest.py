import os

# One BLAS thread per process, set before numpy loads (a variable set by the caller wins).
# The suite runs on a few shared cores and its programmes run worker processes of their
# own (sim.parallel.map_jobs); OpenBLAS's threads then wait on one another: on the loaded
# 2-core machine a 153 x 153 solve took 210 ms with its threads and 0.27 ms with one, and
# one CGS mechanical calibration (test_cgs_mechanical, spring_and_coulomb) 205 s and 13.6 s,
# with the same effects and values.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

import mjcf  # noqa: E402
from sim.effects import build_model  # noqa: E402


@pytest.fixture(scope="session")
def cgs_desc():
    return mjcf.load_table("cgs")


@pytest.fixture(scope="session")
def cgs(cgs_desc):
    return build_model(cgs_desc)
