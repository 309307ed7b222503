"""pytest: identifiability, the problem builder's normal equations, compensation, planning and the
calibrate options added for them (joint_errors, holdout, unknown options)."""

import os

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))



def test_identifiability_names_the_lost_directions(inputs):
    m, d, _ = inputs
    ident = lpoe.identifiability(m, d)
    assert ident.identifiable and ident.message == ""
    assert (ident.rank, ident.num_parameters) == (27, 27)  # 6 x 4 + 3 (cobot6, positions)
    lost = dict(ident.not_identifiable)
    assert len(lost) == 15  # 6 x 2 + 3
    assert "joint1.rz" in lost and "commutes" in lost["joint1.rz"]
    assert all(name.startswith("smr1.r") for name in lost if "orientation" in lost[name])
    assert ident.singular_values.shape == (27,)
    assert "rank 27 of 27" in repr(ident)
    # One pose measured again and again cannot identify the model; the message says why.
    same = lpoe.measurements(m, np.repeat(d.q[:1], 30, axis=0), np.repeat(d.positions[:1], 30, axis=0))
    poor = lpoe.identifiability(m, same)
    assert not poor.identifiable and poor.rank < 27
    assert "cannot identify" in poor.message and poor.weakest


def test_gauss_newton_on_the_normal_equations_equals_calibrate(inputs):
    m, d, v = inputs
    p = lpoe.Problem(m, d)
    for _ in range(10):
        ne = p.normal_equations()
        p.update(np.linalg.solve(ne.H, ne.g))
    assert len(ne.names) == ne.H.shape[0] == 27 and ne.g.shape == (27,)
    assert p.names == ne.names and "27 parameters" in repr(p)
    # Plain least squares: the normal equations carry no prior (docs/identifiability.md).
    ref = lpoe.calibrate(m, d, register=False, prior_scale=0).model
    np.testing.assert_allclose(p.model.predict(v.q), ref.predict(v.q), atol=1e-6)
    # The cost is the one the residuals give: 0.5 |P_measured - P_model|^2.
    res = d.positions - p.model.predict(d.q)
    assert p.normal_equations().cost == pytest.approx(0.5 * np.sum(res**2), rel=1e-9)


def test_problem_with_joint_errors(inputs):
    m, d, _ = inputs
    p = lpoe.Problem(m, d, joint_errors="harmonics")
    assert len(p.names) == 27 + 24 and p.names[27] == "harmonics.joint1.sin1"
    ident = lpoe.identifiability(m, d, joint_errors="harmonics")
    assert ident.identifiable and ident.num_parameters == 51
    for _ in range(8):
        ne = p.normal_equations()
        p.update(np.linalg.solve(ne.H, ne.g))
    theta = p.joint_terms["harmonics"]
    assert theta.shape == (24,)
    # The section-4 data carry no harmonics: what is found is within a few standard deviations
    # (sigma^2 H^-1 with the data's 0.03 mm noise; the wrist's are the least certain).
    sd = 0.03 * np.sqrt(np.diag(np.linalg.inv(p.normal_equations().H)))[27:]
    assert np.all(np.abs(theta) < 5 * sd)
    with pytest.raises(lpoe.Error, match="joint_errors"):
        lpoe.Problem(m, d, joint_errors="backlash")


def test_a_prior_added_to_the_normal_equations_holds_its_parameter(inputs):
    m, d, _ = inputs
    p = lpoe.Problem(m, d, sigma=0.03)
    k = p.normal_equations().names.index("smr1.tx")
    total = np.zeros(27)
    for _ in range(10):
        ne = p.normal_equations()
        H, g = ne.H.copy(), ne.g.copy()
        w = 1e12  # the caller's prior: smr1.tx stays where it started
        H[k, k] += w
        g[k] += w * (0.0 - total[k])
        x = np.linalg.solve(H, g)
        p.update(x)
        total += x
    assert abs(total[k]) < 1e-6
    free = lpoe.Problem(m, d, sigma=0.03)
    for _ in range(10):
        ne = free.normal_equations()
        free.update(np.linalg.solve(ne.H, ne.g))
    assert p.normal_equations().cost > free.normal_equations().cost  # the prior costs fit
    with pytest.raises(lpoe.Error, match="update: expected 27"):
        p.update(np.zeros(3))


@pytest.fixture(scope="module")
def calibrated(inputs):
    m, d, v = inputs
    return lpoe.calibrate(m, d, verify=v).model


def test_compensate_joint_program_reaches_the_nominal_poses(inputs, calibrated):
    m, _, _ = inputs
    Q = np.random.default_rng(7).uniform(-2.0, 2.0, size=(40, 6))
    c = lpoe.compensate(calibrated, joints=Q, nominal=m)
    assert len(c) == 40 and c.q.shape == (40, 6)
    ok = np.array([s == "ok" for s in c.status])
    assert ok.sum() >= 32  # the others: a target out of the calibrated robot's reach, a branch change
    # The calibrated robot at the compensated joints is where the nominal robot was planned to be.
    np.testing.assert_allclose(calibrated.predict(c.q[ok]), m.predict(Q[ok]), atol=1e-6)
    np.testing.assert_allclose(c.correction, np.linalg.norm(c.q - Q, axis=1), atol=1e-12)
    for k in np.flatnonzero(ok)[:5]:  # pose targets: the orientation is reached too
        np.testing.assert_allclose(calibrated.pose(c.q[k])[:3, :3], m.pose(Q[k])[:3, :3], atol=1e-9)
    # The corrected targets: the nominal tool pose at the compensated joints.
    np.testing.assert_allclose(c.corrected, m.predict(c.q), atol=1e-9)
    assert c.corrected_quaternions.shape == (40, 4)
    assert "40 rows" in repr(c)


def test_compensate_targets_mode_and_bad_input(inputs, calibrated):
    m, _, _ = inputs
    Q = np.random.default_rng(8).uniform(-1.5, 1.5, size=(20, 6))
    targets = m.predict(Q)
    c = lpoe.compensate(calibrated, targets, seeds=Q)
    ok = np.array([s == "ok" for s in c.status])
    assert ok.sum() >= 18
    np.testing.assert_allclose(calibrated.predict(c.q[ok]), targets[ok], atol=1e-6)
    assert c.corrected is None
    with pytest.raises(lpoe.Error, match="seeds"):
        lpoe.compensate(calibrated, targets)
    with pytest.raises(lpoe.Error, match="nominal"):
        lpoe.compensate(calibrated, joints=Q)
    with pytest.raises(lpoe.Error, match=r"shape \(M, 3\)"):
        lpoe.compensate(calibrated, targets[:, :2], seeds=Q)


def test_plan_beats_random_plans(inputs):
    m, _, _ = inputs
    plan = lpoe.plan(m, 30, candidate_count=600, workspace_count=200, random_draws=5)
    assert plan.q.shape == (30, 6) and len(plan) == 30
    np.testing.assert_array_equal(plan.candidates[plan.candidate_rows], plan.q)
    assert plan.quality["rank"] == plan.num_parameters == 27
    assert plan.quality["predicted_rms"] < plan.random_predicted_rms
    # With the default unmodelled error (docs/planning.md): the plan's predicted error is below the
    # random plans'.
    assert 0 < plan.predicted_error <= plan.random_predicted_error
    assert plan.pool["offered"] == 600 and plan.pool["feasible"] <= 600
    cand = np.random.default_rng(3).uniform(-np.pi, np.pi, size=(300, 6))
    p2 = lpoe.plan(m, 25, candidates=cand, criterion="A", random_draws=3)
    np.testing.assert_array_equal(cand[p2.candidate_rows], p2.q)
    # Planning for the harmonics too: more parameters to determine, still full rank.
    p3 = lpoe.plan(m, 40, candidate_count=600, workspace_count=200, random_draws=3,
                   joint_errors="harmonics")
    assert p3.num_parameters > 27 and p3.quality["rank"] == p3.num_parameters
    with pytest.raises(lpoe.Error, match="joint_errors"):
        lpoe.plan(m, 10, joint_errors="backlash")
    with pytest.raises(lpoe.Error, match="criterion"):
        lpoe.plan(m, 10, criterion="Z")
    with pytest.raises(lpoe.Error, match="tracker"):
        lpoe.plan(m, 10, max_range=2000.0)


def test_calibrate_options_pass_through(inputs):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match="unknown option 'colour'.*solver"):
        lpoe.calibrate(m, d, colour="red")
    with pytest.raises(lpoe.Error, match="joint_errors"):
        lpoe.calibrate(m, d, joint_errors="backlash")
    with pytest.raises(lpoe.Error, match="max_iterations: cannot use str"):
        lpoe.calibrate(m, d, max_iterations="many")
    r = lpoe.calibrate(m, d, holdout=0.3)
    assert r.converged
    assert r.report["verification"]["after"]["norm"]["rms"] < 0.1


def test_calibrate_with_joint_errors(inputs):
    m, d, v = inputs
    r = lpoe.calibrate(m, d, verify=v, joint_errors="harmonics")
    assert r.termination in ("converged", "not identifiable")
    if r.converged:
        # The harmonics found in data without any stay small, and the verification is as good.
        after = r.report["verification"]["after"]["norm"]["rms"]
        assert after < 0.1


COMPLIANCE_YAML = """joint_errors:
  compliance:
    - joint: joint2
      links:
        joint2: [2.0e-5, 8.0e-5, -1.8e-4, 2.5e-3]
        joint3: [1.8e-5, 1.8e-3, 5.9e-4, 4.6e-4]
        joint4: [4.0e-6, 2.0e-4, 1.0e-4, 1.0e-4]
    - joint: joint3
      links:
        joint3: [9.0e-5, 9.0e-3, 3.0e-3, 2.3e-3]
        joint4: [2.0e-5, 1.0e-3, 5.0e-4, 5.0e-4]
"""


def test_gravity_tilt_in_problem_and_plan(inputs, tmp_path):
    """'tilt' after compliance: a Problem gets the tilt's two parameters (their columns are zero
    until there are compliance values); a plan accounts for the tilt only for a model that
    carries compliance values and refuses it with the reason otherwise."""
    m, d, _ = inputs
    base = open(os.path.join(DATA, "cobot6.yaml")).read()
    (tmp_path / "compliant.yaml").write_text(base + COMPLIANCE_YAML)
    mc = lpoe.read_model(str(tmp_path / "compliant.yaml"))

    p = lpoe.Problem(m, d, joint_errors="compliance,tilt")
    without = lpoe.Problem(m, d, joint_errors="compliance")
    assert p.names[-2:] == ["gravity.tilt1", "gravity.tilt2"]
    assert len(p.names) == len(without.names) + 2
    H = p.normal_equations().H
    assert H[-1, -1] == 0 and H[-2, -2] == 0  # no compliance values: the tilt is not seen
    Hc = lpoe.Problem(mc, d, joint_errors="compliance,tilt").normal_equations().H
    assert Hc[-1, -1] > 0 and Hc[-2, -2] > 0
    with pytest.raises(lpoe.Error, match="compliance"):
        lpoe.Problem(m, d, joint_errors="tilt")

    with pytest.raises(lpoe.Error, match="carries no compliance values"):
        lpoe.plan(m, 40, joint_errors="compliance,tilt")
    with pytest.raises(lpoe.Error, match="compliance"):
        lpoe.plan(mc, 40, joint_errors="harmonics,tilt")
    # The tilt's columns are what this is about, not the exchange on an unmodelled error.
    opts = dict(candidate_count=600, workspace_count=200, random_draws=3, unmodelled_error=0)
    tilted = lpoe.plan(mc, 60, joint_errors="compliance,tilt", **opts)
    plain = lpoe.plan(mc, 60, joint_errors="compliance", **opts)
    assert tilted.gravity_tilt and not plain.gravity_tilt
    assert tilted.num_parameters == plain.num_parameters + 2
    assert tilted.quality["rank"] == tilted.num_parameters
    assert lpoe.plan(mc, 60, joint_errors="auto", **opts).gravity_tilt
    assert not lpoe.plan(m, 60, joint_errors="auto", **opts).gravity_tilt


def test_plan_takes_the_unmodelled_error_as_lpoe_plan(inputs):
    """unmodelled_error= and unmodelled_length= as lpoe_plan's flags: the default (no residual
    layer) is 0.03 mm given, 0 plans for the noise alone, a larger error predicts a larger error;
    out of range and contact plans refused."""
    m, _, _ = inputs
    opts = dict(candidate_count=300, workspace_count=100, random_draws=2, noise_sigma=0.01)
    default = lpoe.plan(m, 30, **opts)
    given = lpoe.plan(m, 30, unmodelled_error=0.03, **opts)
    assert np.array_equal(default.q, given.q)
    assert default.predicted_error == given.predicted_error
    none = lpoe.plan(m, 30, unmodelled_error=0, **opts)
    small = lpoe.plan(m, 30, unmodelled_error=0.01, **opts)
    large = lpoe.plan(m, 30, unmodelled_error=0.1, unmodelled_length=0.5, **opts)
    assert 0 < none.predicted_error < small.predicted_error < given.predicted_error
    assert given.predicted_error < large.predicted_error
    with pytest.raises(lpoe.Error, match="unmodelled_error"):
        lpoe.plan(m, 30, unmodelled_error=-1, **opts)
    with pytest.raises(lpoe.Error, match="unmodelled_length"):
        lpoe.plan(m, 30, unmodelled_length=float("nan"), **opts)
    with pytest.raises(lpoe.Error, match="unmodelled_error is for tracker plans"):
        lpoe.plan(m, 30, measurement="ballbar", unmodelled_error=0)


def test_joint_error_terms_come_from_the_registry(inputs, tmp_path):
    """The term names joint_errors= accepts are the registry's, each usable alone or in a list; a
    model's joint_errors holds what its YAML carries, in registry order."""
    m, d, _ = inputs
    names = lpoe.joint_error_terms()
    assert names[:2] == ["compliance", "harmonics"] and "gear_ratio" in names
    for name in names:
        p = lpoe.Problem(m, d, joint_errors=name)
        assert any(n.startswith(name + ".") for n in p.names)
    both = lpoe.Problem(m, d, joint_errors="gear_ratio,compliance")
    first = [n.split(".")[0] for n in both.names if n.split(".")[0] in names]
    assert first.index("compliance") < first.index("gear_ratio")  # registry order
    with pytest.raises(lpoe.Error, match="gear_ratio"):  # the message lists the registry
        lpoe.Problem(m, d, joint_errors="backlash")
    base = open(os.path.join(DATA, "cobot6.yaml")).read()
    (tmp_path / "geared.yaml").write_text(
        base + COMPLIANCE_YAML + "  gear_ratio:\n    - joint: joint2\n      s: 2.5e-4\n")
    mg = lpoe.read_model(str(tmp_path / "geared.yaml"))
    assert list(mg.joint_errors) == ["compliance", "gear_ratio"]
    assert mg.joint_errors["gear_ratio"] == [0, 2.5e-4, 0, 0, 0, 0]
    assert m.joint_errors == {}
