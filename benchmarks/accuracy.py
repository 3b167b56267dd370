"""Accuracy-versus-cost study and stability sweep (issue 4). Same as `python -m taichimyxo bench accuracy` /
`bench stability`; see taichimyxo/bench_accuracy.py for what is measured and benchmarks/results/ACCURACY.md for the
reading.

    python benchmarks/accuracy.py [--quick] [--stability [--write-limits]] [--out benchmarks/results]

Results go to benchmarks-results/ in the current directory unless --out names a folder (`--out benchmarks/results`
updates the committed study); --write-limits also rewrites taichimyxo/stability_limits.json from the sweep.
"""
import argparse
import sys

from taichimyxo import bench_accuracy

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="reduced version (a few minutes)")
    p.add_argument("--stability", action="store_true", help="run the stability sweep instead")
    p.add_argument("--out", default=bench_accuracy.DEFAULT_OUT)
    p.add_argument("--write-limits", action="store_true",
                   help="with --stability: rewrite taichimyxo/stability_limits.json (the limits the program enforces)")
    a = p.parse_args()
    if a.stability:
        sys.exit(bench_accuracy.stability_main(quick=a.quick, out_dir=a.out, write_limits=a.write_limits))
    sys.exit(bench_accuracy.main(quick=a.quick, out_dir=a.out))
