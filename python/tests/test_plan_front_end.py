"""lpoe.plan for ballbar and touch-probe poses (measurement='ballbar' | 'plane', as lpoe_plan
--measurement) and for a recalibration with a prior (prior=, prior_free=, as lpoe_plan --prior and
--prior_free): the same library calls as the tool, so the same inputs and seeds give the same
poses, which these tests check against the tool's files; and the refusals of options that do not
apply, by name."""
import json
import os
import re
import subprocess

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
CLI = os.environ.get("LPOE_CALIBRATE")
PLAN = os.path.join(os.path.dirname(CLI), "lpoe_plan") if CLI else None
SIMULATE = os.path.join(os.path.dirname(CLI), "lpoe_simulate") if CLI else None

pytestmark = pytest.mark.skipif(PLAN is None or not os.path.exists(PLAN),
                                reason="LPOE_CALIBRATE (the built tools) not given")

MODEL = os.path.join(DATA, "cobot6.yaml")
# Three faces of a cube in front of cobot6 (outward normals, n.x = d in mm), their centres.
PLANES = np.array([[1, 0, 0, 420], [0, 1, 0, 150], [0, 0, 1, 250]], float)
CENTRES = np.array([[420, 120, 220], [390, 150, 220], [390, 120, 250]], float)


def _flag(rows):
    return ";".join(",".join(repr(float(v)) for v in row) for row in rows)


def _tool_plan(tmp_path, *flags):
    """lpoe_plan's CSV (joint values, the last columns' names) and its JSON report."""
    out = tmp_path / "plan.csv"
    run = subprocess.run([PLAN, f"--output={out}", "--quiet"] + list(flags),
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    lines = [l for l in out.read_text().splitlines() if not l.startswith("#")]
    header = lines[0].split(",")
    n = sum(1 for h in header if re.fullmatch(r"q\d+", h))
    rows = [l.split(",") for l in lines[1:]]
    q = np.array([[float(v) for v in r[:n]] for r in rows])
    names = [r[n] if len(r) > n else "" for r in rows]
    report = json.loads((tmp_path / "plan.json").read_text())
    return q, names, report


@pytest.fixture(scope="module")
def pivots(tmp_path_factory):
    """Three pivots where lpoe_simulate places them for cobot6 (from its comment line)."""
    d = tmp_path_factory.mktemp("pivots")
    subprocess.run([SIMULATE, f"--model={MODEL}", "--measurement=ballbar", "--count=3",
                    f"--output={d / 'bar.csv'}", "--quiet"], check=True)
    line = next(l for l in (d / "bar.csv").read_text().splitlines() if "pivots (" in l)
    found = re.findall(r"\(([^)]*)\)", line[line.index("pivots ("):])
    return np.array([[float(v) for v in p.split()] for p in found])


def test_ballbar_plan_is_the_tools(tmp_path, pivots):
    m = lpoe.read_model(MODEL)
    p = lpoe.plan(m, 40, measurement="ballbar", pivots=pivots, samples_per_feature=150,
                  bar_length=160.0, stroke=0.8, seed=4, random_draws=7)
    q, names, report = _tool_plan(tmp_path, f"--model={MODEL}", "--measurement=ballbar",
                                  f"--pivots={_flag(pivots)}", "--count=40",
                                  "--samples_per_feature=150", "--bar_length=160",
                                  "--stroke=0.8", "--seed=4", "--random_draws=7")
    assert isinstance(p, lpoe.ContactPlan) and len(p) == 40 and p.q.shape == (40, 6)
    # The tool writes each number in its shortest form that reads back exactly.
    np.testing.assert_array_equal(p.q, q)
    assert p.features == names
    np.testing.assert_array_equal(p.candidates[p.candidate_rows], p.q)
    assert p.num_parameters == report["parameters"]
    assert p.log_det == pytest.approx(report["plan"]["D_log_det"], rel=1e-12)
    assert p.random_best_log_det == pytest.approx(report["random_plans"]["best_D_log_det"],
                                                  rel=1e-12)
    assert p.pool["feasible"] == report["candidates"]["feasible"] == len(p.candidates)
    assert len(p.random_log_det) == 7 and p.log_det > p.random_best_log_det
    # Every pivot gets poses, and every planned ball sits within the stroke of the bar's length on
    # the nominal model.
    assert set(p.features) == {"pivot1", "pivot2", "pivot3"}
    ball = m.predict(p.q)
    k = np.array([int(f[5:]) - 1 for f in p.features])
    r = np.linalg.norm(ball - pivots[k], axis=1)
    assert np.all(np.abs(r - 160.0) <= 0.8 + 1e-6)


def test_probe_plan_is_the_tools(tmp_path):
    m = lpoe.read_model(MODEL)
    p = lpoe.plan(m, 35, measurement="plane", planes=PLANES, face_centres=CENTRES,
                  face_radius=30.0, probe_radius=2.0, samples_per_feature=80, random_draws=4)
    q, names, report = _tool_plan(tmp_path, f"--model={MODEL}", "--measurement=plane",
                                  f"--planes={_flag(PLANES)}", f"--face_centres={_flag(CENTRES)}",
                                  "--face_radius=30", "--probe_radius=2", "--count=35",
                                  "--samples_per_feature=80", "--random_draws=4")
    np.testing.assert_array_equal(p.q, q)
    assert p.features == names
    assert p.log_det == pytest.approx(report["plan"]["D_log_det"], rel=1e-12)
    # Every tip one probe radius off its face, within the face's circle.
    tip = m.predict(p.q)
    faces = ["face_x", "face_y", "face_z"]  # three planes are named so, in the order given
    k = np.array([faces.index(f) for f in p.features])
    np.testing.assert_allclose(np.einsum("ij,ij->i", tip, PLANES[k, :3]) - PLANES[k, 3], 2.0,
                               atol=1e-6)
    assert set(p.features) == set(faces)


def test_contact_plan_refuses_what_does_not_apply(pivots):
    m = lpoe.read_model(MODEL)
    for option in [dict(criterion="A"), dict(tracker=[2000, 0, 500]), dict(joint_errors="harmonics"),
                   dict(candidate_count=100), dict(keep_out=np.zeros((1, 6))),
                   dict(noise_sigma=0.01)]:
        name = next(iter(option))
        with pytest.raises(lpoe.Error, match=f"^{name} is for tracker plans"):
            lpoe.plan(m, 40, measurement="ballbar", pivots=pivots, **option)
    with pytest.raises(lpoe.Error, match="takes no prior"):
        lpoe.plan(m, 40, measurement="ballbar", pivots=pivots, prior=MODEL)
    with pytest.raises(lpoe.Error, match="needs pivots"):
        lpoe.plan(m, 40, measurement="ballbar")
    with pytest.raises(lpoe.Error, match="pivots is for measurement='ballbar'"):
        lpoe.plan(m, 40, measurement="plane", planes=PLANES, pivots=pivots)
    with pytest.raises(lpoe.Error, match="give unit normals"):
        lpoe.plan(m, 40, measurement="plane", planes=PLANES * 2)
    with pytest.raises(lpoe.Error, match="--stroke in"):
        lpoe.plan(m, 40, measurement="ballbar", pivots=pivots, stroke=500.0)
    with pytest.raises(lpoe.Error, match="bar_length is for measurement"):
        lpoe.plan(m, 40, bar_length=200.0)
    with pytest.raises(lpoe.Error, match="measurement must be position, ballbar or plane"):
        lpoe.plan(m, 40, measurement="laser")
    # Fewer poses than parameters: refused with the candidates' count, as the tool's exit 3.
    with pytest.raises(lpoe.Error, match="cannot identify the 30 parameters"):
        lpoe.plan(m, 5, measurement="ballbar", pivots=pivots, samples_per_feature=50)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A calibrated cobot6 with its covariance block (the prior of a recalibration)."""
    m = lpoe.read_model(MODEL)
    d = lpoe.read_measurements(os.path.join(DATA, "section4", "identification.csv"), m)
    path = tmp_path_factory.mktemp("prior") / "cal.yaml"
    lpoe.calibrate(m, d).write(str(path))
    return str(path)


def test_plan_with_a_prior_is_the_tools(tmp_path, calibrated):
    small = ["--candidate_count=400", "--workspace_count=150", "--random_draws=3"]
    kw = dict(candidate_count=400, workspace_count=150, random_draws=3)
    q, _, report = _tool_plan(tmp_path, f"--prior={calibrated}", "--count=20", *small)
    p = lpoe.plan(None, 20, prior=calibrated, **kw)
    np.testing.assert_allclose(p.q, q, rtol=0, atol=1e-12)
    assert p.candidate_rows == report["candidate_rows"]
    # The same plan from the prior as an lpoe.Prior, with the model given.
    p2 = lpoe.plan(lpoe.read_model(calibrated), 20, prior=lpoe.read_prior(calibrated), **kw)
    assert p2.candidate_rows == p.candidate_rows
    # The prior moves the plan (its information is where the poses need not go), and so does
    # freeing a frame of it; both as the tool.
    plain = lpoe.plan(lpoe.read_model(calibrated), 20, **kw)
    assert plain.candidate_rows != p.candidate_rows
    q3, _, report3 = _tool_plan(tmp_path, f"--prior={calibrated}", "--prior_free=joint5,joint3",
                                "--count=20", "--noise_sigma=0.02", *small)
    p3 = lpoe.plan(None, 20, prior=calibrated, prior_free=["joint5", "joint3"], noise_sigma=0.02,
                   **kw)
    np.testing.assert_allclose(p3.q, q3, rtol=0, atol=1e-12)
    assert p3.candidate_rows == report3["candidate_rows"] != p.candidate_rows
    with pytest.raises(lpoe.Error, match="prior_free: 'joint9' is no joint or tool"):
        lpoe.plan(None, 20, prior=calibrated, prior_free="joint9", **kw)
    with pytest.raises(lpoe.Error, match="prior_free needs prior"):
        lpoe.plan(lpoe.read_model(calibrated), 20, prior_free="joint5", **kw)
    with pytest.raises(lpoe.Error, match="model: None needs prior"):
        lpoe.plan(None, 20, **kw)
