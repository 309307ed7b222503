"""pytest: lpoe.calibrate against lpoe_calibrate, the two solvers, bad options."""
import os
import subprocess

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
CLI = os.environ.get("LPOE_CALIBRATE")


def test_calibrate_default_data(inputs):
    m, d, v = inputs
    r = lpoe.calibrate(m, d, verify=v)
    assert r.converged and r.termination == "converged"
    assert r.verdict == "pass"
    rep = r.report
    assert rep["solver"]["converged"] is True
    after = rep["verification"]["after"]["norm"]["rms"]
    assert after < 0.1  # sigma 0.03 mm per axis: about 0.06 mm in norm
    # The report's figure is the model's own error on the verification rows.
    err = np.linalg.norm(v.positions - r.model.predict(v.q), axis=1)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(after, rel=1e-9)
    before = rep["verification"]["before"]["norm"]["rms"]
    assert before > 100 * after


@pytest.mark.skipif(CLI is None, reason="LPOE_CALIBRATE (the built tool) not given")
@pytest.mark.parametrize("flags,options", [
    ([], {}),
    (["--solver=ceres"], {"solver": "ceres"}),
    (["--joint_errors=harmonics"], {"joint_errors": "harmonics"}),
    (["--joint_errors=auto"], {"joint_errors": "auto"}),
    (["--residual_model=gp"], {"residual_model": "gp"}),
    (["--holdout=0.25", "--split_seed=4"], {"holdout": 0.25, "split_seed": 4}),
    (["--holdout=0.25", "--split=sequential", "--joint_errors=auto"],
     {"holdout": 0.25, "split": "sequential", "joint_errors": "auto"}),
])
def test_same_model_bytes_as_the_tool(inputs, tmp_path, flags, options):
    m, d, v = inputs
    cli_yaml = tmp_path / "cli.yaml"
    if "holdout" in options:  # the tool holds out rows of --measurements (no --verify)
        ident = os.path.join(DATA, "section4", "identification.csv")
        flags = flags + [f"--measurements={ident}"]
    subprocess.run([CLI, "--plots_dir=", f"--output={cli_yaml}"] + flags, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    py_yaml = tmp_path / "py.yaml"
    verify = None if "holdout" in options else v
    lpoe.write_model(str(py_yaml), lpoe.calibrate(m, d, verify=verify, **options).model)
    # The tool appends the estimate's covariance block (docs/file_formats.md); the model is the same.
    cli = cli_yaml.read_bytes()
    cut = cli.find(b"# covariance of the estimate")
    assert cut > 0
    assert py_yaml.read_bytes() == cli[:cut]


def test_solvers_agree(inputs):
    m, d, v = inputs
    a = lpoe.calibrate(m, d, solver="linear").model.predict(v.q)
    b = lpoe.calibrate(m, d, solver="ceres").model.predict(v.q)
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_bad_options_raise(inputs):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match="solver"):
        lpoe.calibrate(m, d, solver="magic")
    with pytest.raises(lpoe.Error, match="loss needs solver='ceres'"):
        lpoe.calibrate(m, d, loss="huber")
    with pytest.raises(lpoe.Error, match="kfold"):
        lpoe.calibrate(m, d, kfold=1)
    with pytest.raises(lpoe.Error, match="split: expected 'random' or 'sequential', got 'time'"):
        lpoe.calibrate(m, d, holdout=0.3, split="time")


def test_too_few_rows_is_not_identifiable(inputs):
    m, d, _ = inputs
    r = lpoe.calibrate(m, d.subset(list(range(5))))
    assert not r.converged
    assert r.termination == "not_identifiable" or "identif" in r.termination
    assert r.report is None


def test_joint_errors_auto(inputs, tmp_path):
    """joint_errors='auto' picks a set with harmonics when the data carry them (sigma 0.01 mm)."""
    m, _, _ = inputs
    base = open(os.path.join(DATA, "cobot6.yaml")).read()
    coeffs = [[1.5e-4, -0.8e-4, 0.6e-4, 1.1e-4], [-1.2e-4, 0.9e-4, -0.7e-4, 0.5e-4],
              [0.8e-4, 1.3e-4, 0.4e-4, -0.9e-4], [1.1e-4, -0.6e-4, 0.9e-4, 0.3e-4],
              [-0.9e-4, 0.7e-4, 0.5e-4, 1.0e-4], [0.6e-4, 0.4e-4, -0.8e-4, 0.7e-4]]
    yaml = base + "joint_errors:\n  harmonics:\n" + "".join(
        f"    - joint: joint{j + 1}\n      coefficients: {c}\n" for j, c in enumerate(coeffs))
    (tmp_path / "truth.yaml").write_text(yaml)
    truth = lpoe.read_model(str(tmp_path / "truth.yaml"))
    rng = np.random.default_rng(5)
    q = rng.uniform(-np.pi, np.pi, size=(300, 6))
    positions = truth.predict(q) + rng.normal(0, 0.01, size=(300, 3))
    ident = lpoe.measurements(m, q[:200], positions[:200])
    verify = lpoe.measurements(m, q[200:], positions[200:])
    auto = lpoe.calibrate(m, ident, verify=verify, joint_errors="auto", register=False)
    none = lpoe.calibrate(m, ident, verify=verify, register=False)
    assert auto.converged and none.converged
    sel = auto.report["joint_errors"]["selection"]
    assert [c["terms"] for c in sel["candidates"]][0] == "none"
    assert "harmonics" in sel["chosen"]
    rms_auto = auto.report["verification"]["after"]["norm"]["rms"]
    rms_none = none.report["verification"]["after"]["norm"]["rms"]
    assert rms_auto < 0.5 * rms_none
    # The report's figure is the calibrated model's own prediction, joint errors included.
    err = np.linalg.norm(verify.positions - auto.model.predict(verify.q), axis=1)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(rms_auto, rel=1e-9)
    with pytest.raises(lpoe.Error, match="joint_errors"):
        lpoe.calibrate(m, ident, joint_errors="backlash")


def test_residual_layer_is_carried_and_predicted(inputs):
    m, d, v = inputs
    r = lpoe.calibrate(m, d, verify=v, residual_model="gp")
    assert r.converged and r.model.has_residual_layer
    rep = r.report["residual_model"]
    assert rep["requested"] == "gp" and rep["fitted"] is True
    # The report's held-out figure is the model's own error, layer included (predict adds it).
    after = r.report["verification"]["after"]["norm"]["rms"]
    err = np.linalg.norm(v.positions - r.model.predict(v.q), axis=1)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(after, rel=1e-9)
    without = rep["verification_without_layer"]["norm"]["rms"]
    assert after != without
    # Its YAML carries the layer: the same predictions after a round trip.
    back = lpoe.model_from_yaml(r.model.to_yaml(), "calibrated.yaml")
    assert back.has_residual_layer
    np.testing.assert_allclose(back.predict(v.q), r.model.predict(v.q), rtol=0, atol=1e-9)
    sd = back.predict_std(v.q)
    assert sd.shape == (v.q.shape[0],) and np.all(sd > 0)
    assert np.all(sd <= rep["layer"]["signal_std"] + 1e-12)
    with pytest.raises(lpoe.Error, match="no residual layer"):
        m.predict_std(v.q)


def test_write_model_urdf_warns_what_it_leaves_out(inputs, tmp_path):
    m, d, v = inputs
    r = lpoe.calibrate(m, d, verify=v, residual_model="gp")
    with pytest.warns(UserWarning, match="residual layer"):
        lpoe.write_model(str(tmp_path / "layered.urdf"), r.model)
    assert lpoe.read_model(str(tmp_path / "layered.urdf")).has_residual_layer is False
    # YAML keeps it, without a warning; a geometric model's URDF warns of nothing.
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lpoe.write_model(str(tmp_path / "layered.yaml"), r.model)
        lpoe.write_model(str(tmp_path / "nominal.urdf"), m)
    assert lpoe.read_model(str(tmp_path / "layered.yaml")).has_residual_layer


def test_residual_model_auto_and_bad_value(inputs):
    m, d, v = inputs
    r = lpoe.calibrate(m, d, verify=v, residual_model="auto")
    sel = r.report["residual_model"]["selection"]
    assert [c["model"] for c in sel["candidates"]] == ["none", "gp"]
    assert sel["chosen"] in ("none", "gp")
    assert r.model.has_residual_layer == (sel["chosen"] == "gp")
    with pytest.raises(lpoe.Error, match="residual_model"):
        lpoe.calibrate(m, d, residual_model="kriging")
