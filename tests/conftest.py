import numpy as np
import pytest

import labutils


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def dino():
    """The real dinosaur, or a skip that says why (a fresh clone has no real data)."""
    try:
        return labutils.load_dino()
    except labutils.DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")


def pytest_configure(config):
    config.addinivalue_line("markers", "nbgrader: runs nbgrader's command line on a course in a tmp folder "
                                       "(about 20 s; deselect with -m 'not nbgrader')")
