"""lpoe.compensate_program: a URScript program compensated as lpoe_compensate --program does it."""
import re

import numpy as np
import pytest

import lpoe


def pose_literal(T):
    """p[x, y, z, rx, ry, rz] (m, rotation vector) of a 4 x 4 pose in mm."""
    R = T[:3, :3]
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))  # away from 0 and pi here
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    rv = w / (2 * np.sin(angle)) * angle
    v = list(T[:3, 3] / 1000.0) + list(rv)
    return "p[" + ", ".join("%.12f" % x for x in v) + "]"


def test_compensate_program(inputs):
    m, d, v = inputs
    cal = lpoe.calibrate(m, d, verify=v).model
    q1 = np.array([0.2, -0.4, 0.9, 0.1, 0.6, -0.2])
    q2 = q1 + 0.05
    program = ("def p():\r\n"
               "  movej([" + ", ".join("%.12f" % x for x in q1) + "], a=1.2)  # start\r\n"
               "  movel(" + pose_literal(m.pose(q2)) + ", a=1.2, v=0.25)\r\n"
               "  movel(pose_add(get_actual_tcp_pose(), p[0, 0, 0.01, 0, 0, 0]))\r\n"
               "end\r\n")
    r = lpoe.compensate_program(cal, m, program, language="urscript")
    assert [t["status"] for t in r.targets] == ["compensated", "compensated", "not_compensated"]
    assert "computed at run time" in r.targets[2]["reason"]
    assert r.targets[2]["line"] == 4
    # Only numbers changed: with every number masked, the texts are equal.
    mask = lambda s: re.sub(r"-?[0-9]*\.?[0-9]+", "#", s)
    assert mask(r.text) == mask(program)
    assert r.text != program
    assert '"compensated": 2' in r.report
    # Taught points: nothing selected, nothing changed.
    same = lpoe.compensate_program(cal, m, program, language="urscript", targets_only="none")
    assert same.text == program
    with pytest.raises(lpoe.Error, match="line 2"):
        lpoe.compensate_program(cal, m, "def p():\n  movel(p[0, 0, 0, 0, 0)\nend\n",
                                language="urscript")
    with pytest.raises(lpoe.Error, match="language"):
        lpoe.compensate_program(cal, m, program, language="krl")
