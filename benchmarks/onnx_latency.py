"""Latency of the exported ONNX networks (`stafpipe export`) for one team, onnxruntime on the CPU, beside torch.

Usage: python benchmarks/onnx_latency.py [--robots 10] [--repeats 2000]
Prints one row per network: median and 99th-percentile milliseconds per call with onnxruntime (one intra-op thread,
as a robot's node would run it) and with torch (one thread), for a team of `--robots` robots with random inputs of
the exported shapes (the cost does not depend on the values). Needs the `onnx` extra.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch

from stafpipe.export_onnx import example_inputs, export, load_network, networks


def timed(call, repeats: int) -> tuple[float, float]:
    for _ in range(50):
        call()
    times = []
    for _ in range(repeats):
        began = time.perf_counter()
        call()
        times.append((time.perf_counter() - began) * 1e3)
    return statistics.median(times), float(np.percentile(times, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=2000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = 1, 1
    print(
        f"robots {args.robots}, {args.repeats} calls each, 1 thread (onnxruntime {ort.__version__}, torch "
        f"{torch.__version__})"
    )
    print("| network | onnxruntime median ms | onnxruntime p99 ms | torch median ms | torch p99 ms |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for network in networks():
            path = export(network, "", Path(tmp) / f"{network}.onnx")
            module, _ = load_network(network)
            inputs = example_inputs(network, module, args.robots)
            feed = {k: v.numpy() for k, v in inputs.items()}
            session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
            ort_med, ort_p99 = timed(lambda: session.run(None, feed), args.repeats)
            with torch.inference_mode():
                torch_med, torch_p99 = timed(lambda: module(*inputs.values()), args.repeats)
            print(f"| {network} | {ort_med:.3f} | {ort_p99:.3f} | {torch_med:.3f} | {torch_p99:.3f} |")


if __name__ == "__main__":
    main()
