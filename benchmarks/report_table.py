"""The table of a ``usd-garment bench`` report again, from its ``report.json``: every method ×
level of detail pooled over all inputs, as the bench printed it, or with ``--simulated`` over the
inputs that have a reference simulation only (all figures, collisions and jitter included, on the
same frames as the error: the paper's Table 1), and with ``--inputs GLOB`` over the inputs whose
file name matches GLOB (e.g. ``'arms_*'``: the captures imported with the arms as captured).

Run: ``python benchmarks/report_table.py REPORT_DIR/report.json [--simulated] [--inputs GLOB]``
"""

from __future__ import annotations

import argparse
from fnmatch import fnmatch
from pathlib import Path

from usd_garment.eval.bench import chart_table, load_report, simulated_rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", help="a bench folder's report.json")
    parser.add_argument("--simulated", action="store_true",
                        help="only the inputs with a reference simulation")  # fmt: skip
    parser.add_argument("--inputs", default="*", metavar="GLOB",
                        help="only the inputs whose file name matches GLOB")  # fmt: skip
    args = parser.parse_args()
    rows = [r for r in load_report(args.report) if fnmatch(Path(r.input).name, args.inputs)]
    print(chart_table(simulated_rows(rows) if args.simulated else rows))


if __name__ == "__main__":
    main()
