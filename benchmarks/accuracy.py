"""Accuracy-versus-cost study and stability sweep (issue 4). Same as `python -m taichimyxo bench accuracy` /
`bench stability`; see taichimyxo/bench_accuracy.py for what is measured and benchmarks/results/ACCURACY.md for the
reading.

    python benchmarks/accuracy.py [--quick] [--stability] [--out benchmarks/results]
"""
import argparse
import sys

from taichimyxo import bench_accuracy

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="reduced version (a few minutes)")
    p.add_argument("--stability", action="store_true", help="run the stability sweep instead")
    p.add_argument("--out", default="benchmarks/results")
    a = p.parse_args()
    fn = bench_accuracy.stability_main if a.stability else bench_accuracy.main
    sys.exit(fn(quick=a.quick, out_dir=a.out))
