"""Calibrates the shipped default data set (lpoe_calibrate's default run) with the installed module.

Usage: calibrate_default.py <prefix> <output.yaml>
"""
import os
import sys

import lpoe

prefix, output = sys.argv[1], sys.argv[2]
# The module must come from the installed prefix, not from a build tree.
if not os.path.realpath(lpoe.__file__).startswith(os.path.realpath(prefix) + os.sep):
    sys.exit(f"lpoe imported from {lpoe.__file__}, not from {prefix}")
data = os.path.join(prefix, "share", "lpoe_calib", "data")
model = lpoe.read_model(os.path.join(data, "cobot6.yaml"))
ident = lpoe.read_measurements(os.path.join(data, "section4", "identification.csv"), model)
verify = lpoe.read_measurements(os.path.join(data, "section4", "verification.csv"), model)
result = lpoe.calibrate(model, ident, verify=verify)
if not result.converged:
    sys.exit(f"not converged: {result.message}")
lpoe.write_model(output, result.model)
print(f"{lpoe.__file__}: {result.termination}, verdict {result.verdict}")
