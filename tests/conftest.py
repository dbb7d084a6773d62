import pytest

import mjcf
from sim.effects import build_model


@pytest.fixture(scope="session")
def cgs_desc():
    return mjcf.load_table("cgs")


@pytest.fixture(scope="session")
def cgs(cgs_desc):
    return build_model(cgs_desc)
