"""The Python front end keeps the tools' contract: explicit signatures, every error an
lpoe.Error (wrong types and unknown keywords named), per-row tools in predict, compensate's frame
and TCP, the plan's cell, and read_model's chain options as the flags."""
import inspect
import os

import numpy as np
import pytest

import lpoe

URDF = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "urdf", "ur_like.urdf")


def test_signatures_are_explicit_keyword_only_with_the_tools_defaults():
    sig = inspect.signature(lpoe.calibrate)
    p = sig.parameters
    assert list(p)[:3] == ["model", "data", "verify"]
    assert p["max_iterations"].kind is inspect.Parameter.KEYWORD_ONLY
    assert p["max_iterations"].default == 30 and p["noise_sigma"].default == 0.03
    assert p["sigma"].default is None and p["solver"].default == "linear"
    assert not any(q.kind is inspect.Parameter.VAR_KEYWORD for q in p.values())
    comp = inspect.signature(lpoe.compensate).parameters
    assert comp["frame"].default == "base" and comp["tcp"].default is None
    assert comp["max_iterations"].default == 100 and comp["restarts"].default == 8
    plan = inspect.signature(lpoe.plan).parameters
    assert plan["candidate_count"].default == 5000 and plan["acceptance_angle"].default == 30.0
    for name in ("min_z", "box", "keep_out", "joint_ranges"):
        assert plan[name].kind is inspect.Parameter.KEYWORD_ONLY
    assert "tool" in inspect.signature(lpoe.Model.predict).parameters
    assert "keyword" in lpoe.calibrate.__doc__ or "arguments" in lpoe.calibrate.__doc__


def test_unknown_keywords_and_wrong_types_are_lpoe_errors_naming_them(inputs):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match="unknown option 'tolerance'.*max_iterations"):
        lpoe.compensate(m, joints=np.zeros((1, 6)), nominal=m, tolerance=1.0)
    with pytest.raises(lpoe.Error, match="unknown option 'colour'"):
        lpoe.plan(m, 10, colour="red")
    with pytest.raises(lpoe.Error, match=r"count: cannot use str value 'ten' .*expected int"):
        lpoe.plan(m, "ten")
    with pytest.raises(lpoe.Error, match="missing a required argument: 'count'"):
        lpoe.plan(m)
    with pytest.raises(lpoe.Error, match="wrong type"):
        lpoe.read_measurements(42, m)
    # A TypeError never escapes, and lpoe.Error is what a caller catches.
    with pytest.raises(lpoe.Error):
        m.predict("not joints")
    assert issubclass(lpoe.Error, ValueError)


def test_calibrate_refuses_what_lpoe_calibrate_refuses(inputs):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match=r"--max_iterations must be in \[1, 10000\], got 0"):
        lpoe.calibrate(m, d, max_iterations=0)
    with pytest.raises(lpoe.Error, match=r"--noise_sigma must be in"):
        lpoe.calibrate(m, d, noise_sigma=-1.0)


def test_predict_takes_one_tool_per_row():
    m = lpoe.read_model(URDF, tip_link="flange", tool_links="flange,tool_smr")
    assert m.tool_names == ["flange", "tool_smr"] or m.num_tools == 2
    q = np.random.default_rng(3).uniform(-1.0, 1.0, size=(7, 6))
    tools = [0, 1, 1, 0, 1, 0, 0]
    by_index = m.predict(q, tool=tools)
    by_name = m.predict(q, tool=[["flange", "tool_smr"][t] for t in tools])
    by_array = m.predict(q, tool=np.array(tools, dtype=np.int32))
    for k, t in enumerate(tools):
        np.testing.assert_array_equal(by_index[k], m.predict(q[k:k + 1], tool=t)[0])
    np.testing.assert_array_equal(by_name, by_index)
    np.testing.assert_array_equal(by_array, by_index)
    assert np.linalg.norm(by_index[1] - m.predict(q[1:2], tool=0)[0]) > 1.0
    with pytest.raises(lpoe.Error, match="3 tools for 7 rows"):
        m.predict(q, tool=[0, 1, 0])
    with pytest.raises(lpoe.Error, match="row 2.*no tool named 'smr9'"):
        m.predict(q, tool=["flange", "flange", "smr9", 0, 0, 0, 0])


def test_measured_targets_give_the_tools_of_their_rows(inputs):
    m, d, _ = inputs
    np.testing.assert_array_equal(m.predict(d.q, tool=d.targets), m.predict(d.q, tool=0))


def registered(m):
    """m moved into a tracker frame 2 m away, as a registered calibration is."""
    c = m.copy()
    a = 0.8
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T[:3, 3] = [2000.0, -1500.0, 300.0]
    c.measurement_base = T
    c.set_joint_origin(0, T @ m.joint_origin(0))
    return c, T


def test_compensate_targets_in_the_base_frame_by_default_like_the_tool(inputs):
    m, _, _ = inputs
    c, T = registered(m)
    Q = np.random.default_rng(9).uniform(-1.2, 1.2, size=(30, 6))
    base_targets = m.predict(Q) + np.array([0.2, -0.3, 0.1])
    r = lpoe.compensate(c, base_targets, seeds=Q)  # frame="base"
    ok = np.array([s == "ok" for s in r.status])
    assert ok.sum() >= 27
    reached = c.predict(r.q[ok])  # in the measurement frame
    expected = (T[:3, :3] @ base_targets[ok].T).T + T[:3, 3]
    np.testing.assert_allclose(reached, expected, atol=1e-6)
    same = lpoe.compensate(c, expected, seeds=Q[ok], frame="measurement")
    np.testing.assert_allclose(same.q, r.q[ok], atol=1e-9)
    # Base-frame targets read as measurement-frame ones are metres off: refused, naming the frame.
    with pytest.raises(lpoe.Error, match=r"measurement frame \(--frame=measurement\).*--frame=base"):
        lpoe.compensate(c, base_targets, seeds=Q, frame="measurement")
    with pytest.raises(lpoe.Error, match="frame: expected 'base', 'measurement' or 'link:NAME'"):
        lpoe.compensate(c, base_targets, seeds=Q, frame="tracker")


def test_compensate_for_a_tcp_that_was_not_measured(inputs):
    m, _, _ = inputs
    Q = np.random.default_rng(4).uniform(-1.0, 1.0, size=(10, 6))
    tcp = [5.0, 10.0, 180.0, 0.0, 0.2, 0.0]
    r = lpoe.compensate(m, joints=Q, nominal=m, tcp=tcp)
    assert all(s == "ok" for s in r.status)
    # The nominal model compensated against itself: the program's joints back.
    np.testing.assert_allclose(r.q, Q, atol=1e-7)
    # The TCP's targets are another point than the SMR's: the last joint's frame carries it.
    flange = [m.pose(q) @ np.linalg.inv(m.tool_origin(0)) for q in Q]
    tcp_at = lambda q: (m.pose(q) @ np.linalg.inv(m.tool_origin(0)) @ [5.0, 10.0, 180.0, 1.0])[:3]
    targets = np.array([F @ [5.0, 10.0, 180.0, 1.0] for F in flange])[:, :3]
    t = lpoe.compensate(m, targets, seeds=Q + 0.01, tcp=tcp[:3])
    assert all(s == "ok" for s in t.status)
    np.testing.assert_allclose([tcp_at(q) for q in t.q], targets, atol=1e-6)
    assert np.linalg.norm(m.predict(t.q) - targets, axis=1).min() > 100.0  # not the SMR
    with pytest.raises(lpoe.Error, match="tcp: expected a tool name or"):
        lpoe.compensate(m, targets, seeds=Q, tcp=[1.0, 2.0])
    with pytest.raises(lpoe.Error, match="--tcp or --tool, not both"):
        lpoe.compensate(m, targets, seeds=Q, tcp=tcp, tool=0)


def test_plan_keeps_every_pose_in_the_cell(inputs):
    m, _, _ = inputs
    ranges = np.full((6, 2), np.nan)
    ranges[1] = [-1.6, 0.2]
    p = lpoe.plan(m, 16, candidate_count=800, workspace_count=100, random_draws=2, min_z=0.0,
                  joint_ranges=ranges)
    assert p.q.shape == (16, 6)
    assert np.all(p.q[:, 1] >= -1.6) and np.all(p.q[:, 1] <= 0.2)
    assert np.all(m.predict(p.q)[:, 2] >= 0.0)
    assert p.pool["outside_cell"] > 0
    assert p.visible == [m.tool_names] * 16
    free = lpoe.plan(m, 16, candidate_count=800, workspace_count=100, random_draws=2)
    assert free.pool["outside_cell"] == 0
    with pytest.raises(lpoe.Error, match=r"joint_ranges: expected \(6, 2\)"):
        lpoe.plan(m, 16, joint_ranges=np.zeros((5, 2)))
    with pytest.raises(lpoe.Error, match="box"):
        lpoe.plan(m, 16, box=[0, 0, 0, -1, 1, 1])


UR5_CELL = os.path.join(os.path.dirname(__file__), "..", "..", "tests", "data", "urdf",
                        "ur5_classic_cell.urdf")


def test_compensate_in_the_controller_base_for_a_tcp_on_tool0():
    # Targets in ur_description's `base` (base_link turned by pi), a TCP relative to the
    # flange tool0 (82.3 mm out of wrist_3_link and turned), as a UR controller gives them.
    smrs = ["smr1", "smr2", "smr3"]
    m = lpoe.read_model(UR5_CELL, tool_links=smrs)                          # base frame: world
    t0 = lpoe.read_model(UR5_CELL, base_link="base", tool_links=["tool0"])  # tool0 in `base`
    Q = np.array([[0.4, -1.3, 1.5, -1.9, -1.4, 0.3], [1.0, -0.8, 1.1, -1.2, 0.4, 2.0]])
    targets = np.array([(t0.pose(q) @ [0.0, 0.0, 150.0, 1.0])[:3] for q in Q])
    r = lpoe.compensate(m, targets, seeds=Q + 0.02, frame="link:base", tcp=[0.0, 0.0, 150.0])
    assert all(s == "ok" for s in r.status)
    reached = np.array([(t0.pose(q) @ [0.0, 0.0, 150.0, 1.0])[:3] for q in r.q])
    np.testing.assert_allclose(reached, targets, atol=1e-6)
    # In the last joint's frame (flange= a flange frame of its own) the same numbers are another
    # point: the meaning is the flange's.
    w = lpoe.compensate(m, targets, seeds=Q + 0.02, frame="link:base", tcp=[0.0, 0.0, 150.0],
                        flange="wrist_3_link")
    moved = np.array([(t0.pose(q) @ [0.0, 0.0, 150.0, 1.0])[:3] for q in w.q])
    assert np.linalg.norm(moved - targets, axis=1).min() > 10.0
    with pytest.raises(lpoe.Error, match="no base frame 'nowhere'"):
        lpoe.compensate(m, targets, seeds=Q, frame="link:nowhere", tcp=[0.0, 0.0, 150.0])
