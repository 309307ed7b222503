"""pytest: recalibration with a prior and the fleet prior (docs/recalibration.md):
lpoe.calibrate(..., prior=) and lpoe.fleet_prior(models), against the tools lpoe_calibrate --prior
and lpoe_prior, on a simulated 6R arm with 3 SMRs off the flange axis and a tracker 3 m away."""
import os
import subprocess

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
CLI = os.environ.get("LPOE_CALIBRATE")
PRIOR_TOOL = os.path.join(os.path.dirname(CLI), "lpoe_prior") if CLI else None
NOISE = 0.02  # mm per axis

SMRS = """tools:
  - name: smr1
    origin: {xyz: [60, 0, 90], quaternion: [0, 0, 0, 1]}
  - name: smr2
    origin: {xyz: [-30, 55, 90], quaternion: [0, 0, 0, 1]}
  - name: smr3
    origin: {xyz: [-30, -55, 90], quaternion: [0, 0, 0, 1]}
"""


def _type_model():
    """cobot6 with three SMRs off the flange axis."""
    text = open(os.path.join(DATA, "cobot6.yaml")).read()
    return lpoe.model_from_yaml(text[:text.index("tools:")] + SMRS)


def _rotation(w):
    a = np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if a < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(a) / a * K + (1 - np.cos(a)) / a**2 * K @ K


def _transform(w, v):
    T = np.eye(4)
    T[:3, :3] = _rotation(np.asarray(w, float))
    T[:3, 3] = v
    return T


def _robot(model, rng, mm, mrad):
    """An actual robot: every joint frame and SMR off by about `mm` and `mrad`."""
    r = model.copy()
    for i in range(6):
        r.set_joint_origin(i, r.joint_origin(i) @ _transform(rng.normal(0, mrad * 1e-3, 3),
                                                             rng.normal(0, mm, 3)))
    return r


def _tracker(rng):
    a = rng.uniform(-np.pi, np.pi)
    return _transform([0, 0, rng.uniform(-np.pi, np.pi)],
                      [3000 * np.cos(a), 3000 * np.sin(a), rng.uniform(-200, 200)])


def _measure(robot, zero, poses, T, rng, noise=NOISE):
    """`poses` random configurations, every SMR at each, in tracker frame T (joint zeros `zero`
    added to the commanded values: the robot's actual zeros)."""
    q = rng.uniform(-np.pi, np.pi, (poses, 6))
    q_rows = np.repeat(q, 3, axis=0)
    targets = ["smr1", "smr2", "smr3"] * poses
    p = robot.predict(q_rows + zero, tool=targets)
    p = p @ T[:3, :3].T + T[:3, 3] + rng.normal(0, noise, p.shape)
    return lpoe.measurements(robot, q_rows, p, targets=np.tile([0, 1, 2], poses))


def _held_out(robot, zero, model, rng):
    """RMS distance of `model`'s SMR positions from the robot's over fresh configurations, after a
    rigid fit (models of other sessions are in other tracker frames)."""
    q = np.repeat(rng.uniform(-np.pi, np.pi, (200, 6)), 3, axis=0)
    targets = ["smr1", "smr2", "smr3"] * 200
    actual = robot.predict(q + zero, tool=targets)
    predicted = model.predict(q, tool=targets)
    a, b = predicted - predicted.mean(0), actual - actual.mean(0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    fitted = a @ R.T + actual.mean(0)
    return float(np.sqrt(np.mean(np.sum((fitted - actual) ** 2, axis=1))))


def _write_csv(path, data):
    with open(path, "w") as f:
        f.write("q1,q2,q3,q4,q5,q6,x,y,z,target\n")
        for q, p, t in zip(data.q, data.positions, data.targets):
            f.write(",".join(repr(float(v)) for v in list(q) + list(p)) + f",smr{int(t) + 1}\n")


@pytest.fixture(scope="module")
def maintained(tmp_path_factory):
    """A robot calibrated from 150 poses (written with its covariance), then maintained: joint 3's
    zero +0.2 deg, joint 5's frame 0.3 mm and 1 mrad; 15 new poses from another tracker stand."""
    rng = np.random.default_rng(45)
    type_model = _type_model()
    before = _robot(type_model, rng, 0.5, 1.0)
    zero = np.zeros(6)
    previous = lpoe.calibrate(type_model, _measure(before, zero, 150, _tracker(rng), rng))
    assert previous.converged
    path = str(tmp_path_factory.mktemp("recal") / "cal.yaml")
    previous.write(path)
    after = before.copy()
    after.set_joint_origin(4, after.joint_origin(4) @ _transform([0.001, 0, 0], [0, 0.3, 0]))
    zero_after = zero.copy()
    zero_after[2] = np.radians(0.2)
    fifteen = _measure(after, zero_after, 15, _tracker(rng), rng)
    return dict(previous=previous, path=path, after=after, zero=zero_after, fifteen=fifteen)


def test_prior_and_fifteen_poses_beat_the_fifteen_poses_alone(maintained):
    m = maintained
    r = lpoe.calibrate(None, m["fifteen"], prior=m["path"])
    assert r.converged
    ls = lpoe.calibrate(m["previous"].model, m["fifteen"], prior_scale=0)
    assert ls.converged
    rng = np.random.default_rng(7)
    e_map = _held_out(m["after"], m["zero"], r.model, rng)
    e_ls = _held_out(m["after"], m["zero"], ls.model, np.random.default_rng(7))
    e_prev = _held_out(m["after"], m["zero"], m["previous"].model, np.random.default_rng(7))
    print(f"held out: prior + 15 poses {e_map:.4f} mm, 15 poses alone {e_ls:.4f} mm, "
          f"previous model {e_prev:.4f} mm; changed {[g['name'] for g in r.changed]}")
    assert 1.5 * e_map <= e_ls
    assert 10 * e_map <= e_prev
    names = " ".join(g["name"] for g in r.changed)
    assert "joint3" in names and "joint5" in names
    for g in r.changed:
        assert g["chi2"] > g["dof"]
    # The data's share per parameter: in [0, 1], the report's identified[].data_share.
    share = r.data_share
    ident = r.report["identifiability"]["identified"]
    assert len(share) == len(ident) > 0
    for p in ident:
        assert share[p["name"]] == pytest.approx(p["data_share"], abs=1e-12)
        assert -1e-9 <= p["data_share"] <= 1 + 1e-9
    assert r.report["recalibration"]["changed"] == r.changed
    # Without a prior: no shares, no recalibration key (the report as before).
    assert ls.data_share == {} and "recalibration" not in ls.report


@pytest.mark.skipif(CLI is None, reason="LPOE_CALIBRATE (the built tool) not given")
def test_same_model_as_the_tool_with_prior(maintained, tmp_path):
    m = maintained
    csv = tmp_path / "fifteen.csv"
    _write_csv(csv, m["fifteen"])
    out = tmp_path / "cli.yaml"
    run = subprocess.run([CLI, "--plots_dir=", f"--prior={m['path']}", f"--measurements={csv}",
                          f"--output={out}"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    r = lpoe.calibrate(None, lpoe.read_measurements(str(csv), m["previous"].model),
                       prior=m["path"])
    # The same MAP estimate, groups and covariance block: the same bytes as --output.
    assert out.read_text() == r.yaml
    for g in r.changed:
        assert g["name"] in run.stdout


def test_prior_refusals(maintained, tmp_path):
    m = maintained
    with pytest.raises(lpoe.Error, match="no covariance block"):
        plain = tmp_path / "plain.yaml"
        lpoe.write_model(str(plain), m["previous"].model)
        lpoe.calibrate(None, m["fifteen"], prior=str(plain))
    with pytest.raises(lpoe.Error, match="prior needs prior_scale > 0"):
        lpoe.calibrate(None, m["fifteen"], prior=m["path"], prior_scale=0)
    with pytest.raises(lpoe.Error, match="a model is needed"):
        lpoe.calibrate(None, m["fifteen"])


def test_fleet_prior_matches_lpoe_prior_and_refuses_another_chain(tmp_path):
    rng = np.random.default_rng(8)
    type_model = _type_model()
    paths, models = [], []
    for k in range(3):
        robot = _robot(type_model, rng, 0.2, 0.3)
        c = lpoe.calibrate(type_model, _measure(robot, np.zeros(6), 30, _tracker(rng), rng))
        path = tmp_path / f"robot{k}.yaml"
        c.write(str(path))
        paths.append(str(path))
        models.append(lpoe.read_model(str(path)))
    with pytest.warns(UserWarning, match="needs 7 robots for full rank"):
        fleet = lpoe.fleet_prior(paths, output=str(tmp_path / "fleet_py.yaml"))
    assert fleet.robots == 3
    # From models or from files: the same prior.
    with pytest.warns(UserWarning):
        from_models = lpoe.fleet_prior(models)
    assert from_models.yaml == fleet.yaml
    # The mean is between the robots: each local frame's mean position is their average (to the
    # second order of the mm and mrad spread; joint 1's frame is each session's registration).
    for i in range(1, 6):
        mean_t = np.mean([mm.joint_origin(i)[:3, 3] for mm in models], axis=0)
        assert np.allclose(fleet.model.joint_origin(i)[:3, 3], mean_t, atol=1e-3)
    cov = fleet.covariance
    assert set(cov) >= {"joint2", "smr1"} and cov["joint2"].shape == (6, 6)
    assert np.linalg.matrix_rank(cov["joint2"], tol=1e-12 * np.abs(cov["joint2"]).max()) <= 2
    # Usable as prior=: the fleet's mean is the start.
    r = lpoe.calibrate(None, _measure(_robot(type_model, rng, 0.2, 0.3), np.zeros(6), 20,
                                      _tracker(rng), rng), prior=fleet)
    assert r.converged and r.report["recalibration"]["prior"] == str(tmp_path / "fleet_py.yaml")
    if PRIOR_TOOL and os.path.exists(PRIOR_TOOL):
        out = tmp_path / "fleet_cli.yaml"
        run = subprocess.run([PRIOR_TOOL, f"--models={','.join(paths)}", f"--output={out}"],
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr
        cli = lpoe.read_prior(str(out))
        assert out.read_text() == fleet.yaml
        for name, C in fleet.covariance.items():
            assert np.allclose(cli.covariance[name], C, rtol=1e-9, atol=1e-15)
        # Another chain: lpoe_prior's refusal, word for word.
        other = tmp_path / "five.yaml"
        text = open(paths[1]).read()
        cut = text.index("  - name: joint6")
        other.write_text(text[:cut] + text[text.index("tools:"):].split("covariance:")[0])
        bad = subprocess.run([PRIOR_TOOL, f"--models={paths[0]},{other}",
                              f"--output={tmp_path / 'x.yaml'}"], capture_output=True, text=True)
        assert bad.returncode == 2
        with pytest.raises(lpoe.Error) as e:
            lpoe.fleet_prior([paths[0], str(other)])
        assert f"error: {e.value}\n" == bad.stderr
        assert "one chain" in str(e.value)
    with pytest.raises(lpoe.Error, match="at least 2 calibrated models"):
        lpoe.fleet_prior(paths[:1])
    with pytest.raises(lpoe.Error, match="listed twice"):
        lpoe.fleet_prior([paths[0], paths[0]])
