"""Shared pytest fixtures: the shipped model and section-4 data set."""
import os

import pytest

import lpoe

# In a sanitizer build the suite runs in an interpreter with the sanitizer runtime preloaded
# (python/CMakeLists.txt); the tools it starts carry their own copy and refuse a second one.
if os.environ.pop("LPOE_SANITIZER_PRELOAD", None):
    os.environ.pop("LD_PRELOAD", None)

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))


@pytest.fixture(scope="session")
def inputs():
    """(nominal model, identification rows, verification rows) of the default data set."""
    m = lpoe.read_model(os.path.join(DATA, "cobot6.yaml"))
    d = lpoe.read_measurements(os.path.join(DATA, "section4", "identification.csv"), m)
    v = lpoe.read_measurements(os.path.join(DATA, "section4", "verification.csv"), m)
    return m, d, v
