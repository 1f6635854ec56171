"""The README's headline table holds the figures of bench/results.json, the run that wrote it.

`make bench` writes the table (bench/run.py, write_headline); this test reads the same
figures from the JSON on its own and compares them with the numbers printed in each row,
so a table edited by hand, or one a newer run's JSON no longer matches, fails here.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent
BEGIN, END = "<!-- headline:begin -->", "<!-- headline:end -->"
#: A printed number with its unit: 3.2 KB, 46 ms, 0.852, 7,012.
NUMBER = re.compile(r"(\d[\d,]*(?:\.\d+)?)\s*(KB|MB|GB|ms|s|B)?(?![\w.])")
#: Value of one unit in the JSON's units (bytes, seconds).
UNITS = {None: 1.0, "B": 1.0, "KB": 1e3, "MB": 1e6, "GB": 1e9, "ms": 1e-3, "s": 1.0}


def _office(r: dict[str, Any]) -> list[float]:
    m = r["headline_report"]["models"]
    return [m["parametric"]["memory_bytes"], m["parametric"]["file_bytes"], m["grid"]["memory_bytes"],
            m["octomap"]["memory_bytes"]]


def _iou(r: dict[str, Any]) -> list[float]:
    truth = r["headline_report"]["truth"]
    return [truth[name]["iou"] for name in ("parametric", "grid", "octomap")]


def _scenes(r: dict[str, Any]) -> list[float]:
    row = next(s for s in r["map_quality_summary"] if s["features"] == 10_000)
    return [row["parametric_iou_mean"], row["grid_iou_mean"], row["best_grid_iou_mean"]]


def _lasers(r: dict[str, Any]) -> list[float]:
    logs = r["laser_logs"]
    return [sum(x["positions_with_returns_within_the_body"] for x in logs), sum(x["positions"] for x in logs)]


def _heldout(r: dict[str, Any], pick: Callable[[list[dict[str, Any]]], float]) -> list[float]:
    return [pick(log["rows"]) for log in r["heldout"]["logs"]]


def _world(rows: list[dict[str, Any]], key: str = "auc") -> float:
    return next(x for x in rows if x["model"].startswith("fused map"))[key]


def _best_grid(rows: list[dict[str, Any]]) -> float:
    return max(x["auc"] for x in rows if x["model"].endswith("tuned on the training scans"))


def _byte_grid(rows: list[dict[str, Any]]) -> float:
    return next(x for x in rows if x["model"] == "textbook grid 0.1 m, tuned on the training scans")["bytes"]


def _whole_log(r: dict[str, Any]) -> list[float]:
    row = next(x for x in r["log_map"]["whole_log"] if x["keyframe_share"] is None and not x["exit_status"])
    return [row["cpu_s"]]


#: The start of each row's label, and its figures as results.json holds them (bytes, seconds).
EXPECTED: dict[str, Callable[[dict[str, Any]], list[float]]] = {
    "Office model memory": _office,
    "Office IoU with the truth": _iou,
    "Office fit / extraction": lambda r: [r["speed"]["fit_s"], r["speed"]["extract_s"]],
    "Seven scenes x 3 seeds, mean IoU": _scenes,
    "Fit of 1M features": lambda r: [next(x for x in r["large"] if x["features"] == 1_000_000)["fit_cpu_s"]],
    "Six CARMEN logs": _lasers,
    "Whole-log map, held-out AUC, Intel / FR-079 / ACES / CSAIL: world.occmap": lambda r: _heldout(r, _world),
    "Whole-log map, held-out AUC, Intel / FR-079 / ACES / CSAIL: best tuned grid": lambda r: _heldout(r, _best_grid),
    "world.occmap against a 0.1 m byte grid": lambda r: (_heldout(r, lambda rows: _world(rows, "bytes"))
                                                         + _heldout(r, _byte_grid)),
    "Intel whole log through `occtool map`": _whole_log,
}


@pytest.fixture(scope="module")
def results() -> dict[str, Any]:
    return json.loads((ROOT / "bench" / "results.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def table() -> list[list[str]]:
    """The headline table's rows (label, value, run), the header and rule left out."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert text.count(BEGIN) == 1 and text.count(END) == 1, "README.md needs one pair of headline markers"
    block = text[text.index(BEGIN) + len(BEGIN):text.index(END)].strip().splitlines()
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")] for line in block]
    assert rows[0] == ["figure", "value", "run"] and set(rows[1][0]) == {"-"}
    return rows[2:]


def printed(value: str) -> list[tuple[float, float, str | None]]:
    """The numbers of a value cell: (number, half a unit of its last printed digit, unit)."""
    out = []
    for number, unit in NUMBER.findall(value):
        decimals = len(number.split(".")[1]) if "." in number else 0
        out.append((float(number.replace(",", "")), 0.5 * 10.0 ** -decimals, unit or None))
    return out


def test_every_headline_figure_is_the_runs(results: dict[str, Any], table: list[list[str]]) -> None:
    for label, value, _run in table:
        keys = [key for key in EXPECTED if label.startswith(key)]
        assert len(keys) == 1, f"README headline row {label!r} is not one results.json knows"
        expected = EXPECTED[keys[0]](results)
        shown = printed(value)
        assert len(shown) == len(expected), f"{label}: {value!r} should show {len(expected)} figures"
        for (number, half_digit, unit), figure in zip(shown, expected):
            in_unit = figure / UNITS[unit]
            assert abs(in_unit - number) <= half_digit + 1e-9, (
                f"README headline {label!r}: {value!r} shows {number:g} {unit or ''}, "
                f"bench/results.json has {in_unit:g}: run `make bench` (it writes the table)")


def test_every_row_names_the_run(results: dict[str, Any], table: list[list[str]]) -> None:
    meta = results["meta"]
    run = f"{meta['machine']['commit']}, {meta['date'][:10]}"
    assert table, "the README's headline table is empty"
    assert {row[2] for row in table} == {run}


def test_the_table_has_the_chosen_figures(table: list[list[str]]) -> None:
    labels = [row[0] for row in table]
    missing = [key for key in EXPECTED if not any(label.startswith(key) for label in labels)]
    assert not missing, f"README headline table lacks {missing}"


def test_printed_reads_units_and_precision() -> None:
    assert printed("3.2 KB (file 12.1 KB) / 30.1 MB") == [(3.2, 0.05, "KB"), (12.1, 0.05, "KB"),
                                                          (30.1, 0.05, "MB")]
    assert printed("0 of 7,012") == [(0.0, 0.5, None), (7012.0, 0.5, None)]
    assert printed("46 ms / 11.71 s") == [(46.0, 0.5, "ms"), (11.71, 0.005, "s")]
