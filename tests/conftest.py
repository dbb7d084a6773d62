# First: `import sim` sets one BLAS thread per process before numpy loads (sim/__init__.py
# gives the figures; a variable set by the caller wins), and mjcf loads numpy.
import sim  # noqa: F401

# isort: split
import pytest

import mjcf
from sim.effects import build_model


@pytest.fixture(scope="session")
def cgs_desc():
    return mjcf.load_table("cgs")


@pytest.fixture(scope="session")
def cgs(cgs_desc):
    return build_model(cgs_desc)
