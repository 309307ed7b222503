"""pytest: known SMR nests (lpoe.calibrate fixed_tools=, as lpoe_calibrate --fixed_tools)."""
import os
import subprocess

import numpy as np
import pytest

import lpoe

DATA = os.environ.get("LPOE_DATA_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "data"))
CLI = os.environ.get("LPOE_CALIBRATE")


def test_fixed_tool_is_held_and_recorded(inputs, tmp_path):
    m, d, v = inputs
    assert m.fixed_tools == []
    r = lpoe.calibrate(m, d, verify=v, fixed_tools=["smr1"])
    assert r.converged
    assert r.model.fixed_tools == ["smr1"]
    # Held as given: the tool frame is the nominal one, bit for bit.
    np.testing.assert_array_equal(r.model.tool_origin("smr1"), m.tool_origin("smr1"))
    free = lpoe.calibrate(m, d, verify=v)
    assert free.model.fixed_tools == []
    assert not np.array_equal(free.model.tool_origin("smr1"), m.tool_origin("smr1"))
    # The model file records it, and reading it back keeps it.
    path = tmp_path / "fixed.yaml"
    lpoe.write_model(str(path), r.model)
    assert "fixed: true" in path.read_text()
    assert lpoe.read_model(str(path)).fixed_tools == ["smr1"]
    # One comma-separated string is the same list.
    s = lpoe.calibrate(m, d, verify=v, fixed_tools="smr1")
    np.testing.assert_array_equal(s.model.predict(v.q), r.model.predict(v.q))


def test_bad_fixed_tools_raise(inputs):
    m, d, _ = inputs
    with pytest.raises(lpoe.Error, match="fixed_tools: no tool named 'smr9'.*smr1"):
        lpoe.calibrate(m, d, fixed_tools=["smr9"])
    with pytest.raises(lpoe.Error, match="fixed_tools: an empty name"):
        lpoe.calibrate(m, d, fixed_tools="smr1,,")
    with pytest.raises(lpoe.Error, match="fixed_tools"):
        lpoe.calibrate(m, d, fixed_tools=[1.5])


@pytest.mark.skipif(CLI is None, reason="LPOE_CALIBRATE (the built tool) not given")
def test_same_model_bytes_as_the_tool(inputs, tmp_path):
    m, d, v = inputs
    cli_yaml = tmp_path / "cli.yaml"
    # --force: a nominal tool point held against data whose actual one differs may fail the verdict.
    subprocess.run([CLI, "--plots_dir=", f"--output={cli_yaml}", "--fixed_tools=smr1", "--force"],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    py_yaml = tmp_path / "py.yaml"
    lpoe.write_model(str(py_yaml), lpoe.calibrate(m, d, verify=v, fixed_tools=["smr1"]).model)
    # The tool appends the estimate's covariance block (docs/file_formats.md); the model is the same.
    cli = cli_yaml.read_bytes()
    cut = cli.find(b"# covariance of the estimate")
    assert cut > 0
    assert py_yaml.read_bytes() == cli[:cut]
