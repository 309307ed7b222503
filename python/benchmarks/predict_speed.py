"""Wall time of Model.predict on 10^6 configurations given as one numpy array (one core).

Usage: PYTHONPATH=build/python taskset -c 0 /usr/bin/python3 python/benchmarks/predict_speed.py
Prints the best of 5 runs (acceptance figure of at most 0.2 s). Not a test: a timing.
"""
import os
import time

import numpy as np

import lpoe

HERE = os.path.dirname(os.path.abspath(__file__))
model = lpoe.read_model(os.path.join(HERE, "..", "..", "data", "cobot6.yaml"))
Q = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(1_000_000, 6))
best = best_cpu = float("inf")
for _ in range(5):
    start, start_cpu = time.perf_counter(), time.process_time()
    P = model.predict(Q)
    best = min(best, time.perf_counter() - start)
    best_cpu = min(best_cpu, time.process_time() - start_cpu)
assert P.shape == (1_000_000, 3)
# CPU time too: on a shared machine the wall time includes waiting for the core.
print(f"predict: 10^6 configurations in {best:.3f} s wall, {best_cpu:.3f} s CPU (best of 5)")
