"""Separator detection on spreadsheet exports: csv.Sniffer, clevercsv and pandas side by side.

Each messy file is built from the same 40 measurements (the README's calibration example) in a
dialect that spreadsheets write: a European Excel export (semicolon, decimal comma, BOM, CRLF, an
empty last column, a blank line at the end), tab- and semicolon-separated files, a trailing comma on
every line, units in the header with spaces and brackets, a file of two rows. For each detector the
bench prints whether it found the separator and how long it took per file (median of repeats).

    .venv/bin/python bench/csv_dialect.py            # clevercsv and pandas are optional
"""

from __future__ import annotations

import csv
import io
import statistics
import time

ROWS = [
    (4, 0.0132, 0.07, 0.38, 0.01448), (4, 0.0044, 0.092, 0.65, 0.02287), (4, 0.0044, 0.113, 0.63, 0.02302),
    (4, 0.0044, 0.144, 0.33, 0.01654), (4, 0.0044, 0.05, 0.7, 0.02406), (4, 0.0132, 0.101, 0.59, 0.01789),
    (4, 0.0132, 0.107, 0.61, 0.01847), (4, 0.0088, 0.051, 0.69, 0.02068), (4, 0.0044, 0.01, 0.46, 0.01857),
    (4, 0.0044, 0.146, 0.66, 0.02342), (4, 0.0044, 0.052, 0.73, 0.02441), (4, 0.0088, 0.054, 0.26, 0.01273),
] * 3 + [(4, 0.0088, 0.135, 0.71, 0.02128), (4, 0.0088, 0.092, 0.44, 0.01643),
         (4, 0.0044, 0.076, 0.49, 0.01945), (4, 0.0044, 0.118, 0.29, 0.01574)]
PLAIN = ["balls", "load_N", "speed_m_s", "relative_humidity", "mu_measured"]
UNITS = ["balls", "load [mN]", "speed (mm/s)", "relative humidity [%]", "mu_measured"]


def _file(sep: str, decimal: str = ".", header=PLAIN, rows=ROWS, newline="\n", bom=False, trailing="",
          end="") -> str:
    def cell(v):
        return str(v).replace(".", decimal)
    lines = [sep.join(header) + trailing] + [sep.join(cell(v) for v in r) + trailing for r in rows]
    return ("\ufeff" if bom else "") + newline.join(lines) + newline + end


CASES = {
    "European Excel (; , BOM CRLF, empty last column, blank end line)":
        (";", _file(";", ",", newline="\r\n", bom=True, trailing=";", end="\r\n")),
    "tab-separated, dot decimals": ("\t", _file("\t")),
    "tab-separated, decimal comma": ("\t", _file("\t", ",")),
    "semicolon, dot decimals": (";", _file(";")),
    "comma, a trailing comma on every line": (",", _file(",", trailing=",", end="\n")),
    "comma, units in the header": (",", _file(",", header=UNITS)),
    "semicolon, decimal comma, units in the header": (";", _file(";", ",", header=UNITS)),
    "semicolon, two rows": (";", _file(";", rows=ROWS[:2])),
    "comma, two rows": (",", _file(",", rows=ROWS[:2])),
    "semicolon, decimal comma, one row": (";", _file(";", ",", rows=ROWS[:1])),
    "semicolon, decimal comma, a note column with commas":
        (";", _file(";", ",", header=[*PLAIN, "note"], rows=[(*r, "run 2, after cleaning") for r in ROWS])),
    "comma, quoted note column with semicolons":
        (",", _file(",", header=[*PLAIN, "note"], rows=[(*r, '"dry; 20 C"') for r in ROWS])),
}


def sniffer_any(text):
    return csv.Sniffer().sniff(text[:4096]).delimiter


def sniffer_limited(text):
    return csv.Sniffer().sniff(text[:4096], delimiters=",;\t").delimiter


def clever(text):
    import clevercsv
    dialect = clevercsv.Detector().detect(text[:4096], delimiters=[",", ";", "\t"])
    return None if dialect is None else dialect.delimiter


def pandas_python_engine(text):
    import pandas as pd
    # pandas' sep=None sniffs with csv.Sniffer on the first line; it has no decimal detection.
    frame = pd.read_csv(io.StringIO(text), sep=None, engine="python")
    return {1: None}.get(frame.shape[1], _pandas_sep(text))


def _pandas_sep(text):
    import pandas as pd
    reader = pd.read_csv(io.StringIO(text), sep=None, engine="python", iterator=True)
    return reader._engine.data.dialect.delimiter  # the dialect pandas chose


def main() -> None:
    detectors = {"csv.Sniffer": sniffer_any, "csv.Sniffer(delimiters=',;\\t')": sniffer_limited}
    try:
        import clevercsv
        detectors[f"clevercsv {clevercsv.__version__} (,;\\t)"] = clever
    except ImportError:
        print("clevercsv not installed: skipped")
    try:
        import pandas
        detectors[f"pandas {pandas.__version__} sep=None"] = pandas_python_engine
    except ImportError:
        print("pandas not installed: skipped")
    for name, detect in detectors.items():
        right, times, wrong = 0, [], []
        for case, (sep, text) in CASES.items():
            per = []
            for _ in range(7):
                start = time.perf_counter()
                try:
                    got = detect(text)
                except Exception as exc:  # a detector that gives up
                    got = f"error: {type(exc).__name__}"
                per.append(time.perf_counter() - start)
            times.append(statistics.median(per))
            if got == sep:
                right += 1
            else:
                wrong.append(f"{case}: got {got!r}")
        print(f"{name:40s} right {right} of {len(CASES)}, median {1e3 * statistics.median(times):7.2f} ms "
              f"per file (max {1e3 * max(times):.2f})")
        for line in wrong:
            print(f"    wrong: {line}")


if __name__ == "__main__":
    main()
