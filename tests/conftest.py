import pytest

import mjcf


@pytest.fixture(scope="session")
def cgs_desc():
    return mjcf.load_table("cgs")


@pytest.fixture(scope="session")
def cgs(cgs_desc):
    return mjcf.build(cgs_desc)
