"""lpoe.read_measurements returns the kind of a file: tracker files give lpoe.Measurements
('position' / 'pose'), ballbar and probe files lpoe.ContactMeasurements ('distance' / 'plane')."""
import os

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))


@pytest.fixture(scope="module")
def model():
    return lpoe.read_model(os.path.join(DATA, "cobot6.yaml"))


def test_tracker_file_is_position(model):
    d = lpoe.read_measurements(os.path.join(DATA, "section4", "identification.csv"), model)
    assert d.kind == "position"


def test_ballbar_file(tmp_path, model):
    p = tmp_path / "bar.csv"
    p.write_text("q1,q2,q3,q4,q5,q6,distance,pivot,sigma\n"
                 "0.1,0.2,0.3,0.4,0.5,0.6,150.001,A,0.002\n"
                 "0.1,0.2,0.3,0.4,0.5,0.7,149.5,B,0.004\n")
    d = lpoe.read_measurements(str(p), model)
    assert d.kind == "distance"
    assert len(d) == 2
    assert d.q.shape == (2, 6)
    np.testing.assert_array_equal(d.values, [150.001, 149.5])
    np.testing.assert_array_equal(d.sigmas, [0.002, 0.004])
    np.testing.assert_array_equal(d.features, [0, 1])
    assert d.pivots == ["A", "B"]


def test_plane_file_needs_a_noise(tmp_path, model):
    p = tmp_path / "probe.csv"
    p.write_text("q1,q2,q3,q4,q5,q6,plane,offset\n0,0,0,0,0,0,top,3\n")
    with pytest.raises(lpoe.Error, match=r"probe.csv:1: no 'sigma' column"):
        lpoe.read_measurements(str(p), model)
    d = lpoe.read_measurements(str(p), model, sigma=0.003)
    assert d.kind == "plane"
    assert d.planes == ["top"]
    np.testing.assert_array_equal(d.values, [3.0])
