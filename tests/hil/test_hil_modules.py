"""Each rig run is split by job (issue 12): the run takes data, the analysis computes results
from the files alone, the report shows them. The run and ``utrf hil analyse`` share the
analysis and nothing else: the run imports neither the analysis nor the report, and the
analysis imports neither the run nor the report."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import utrf.hil

HIL = Path(utrf.hil.__file__).resolve().parent


def _imports(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            base = node.module if node.level == 0 else f"utrf.hil.{path.parent.name}.{node.module}"
            out.add(base)
            out |= {f"{base}.{a.name}" for a in node.names}
    return out


@pytest.mark.parametrize("experiment", ["static_loading", "grasp_hold"])
def test_the_run_and_the_analysis_share_nothing_but_the_files(experiment: str) -> None:
    pkg = f"utrf.hil.{experiment}"
    run = _imports(HIL / experiment / "run.py")
    analysis = _imports(HIL / experiment / "analysis.py")
    report = _imports(HIL / experiment / "report.py")
    assert not {f"{pkg}.analysis", f"{pkg}.report"} & run
    assert not {f"{pkg}.run", f"{pkg}.report"} & analysis
    assert f"{pkg}.analysis" in report and f"{pkg}.run" not in report
    assert "utrf.hil.rig" not in analysis | report  # results need no rig


def test_the_cli_analyses_through_the_report() -> None:
    cli = _imports(Path(utrf.hil.__file__).resolve().parents[1] / "cli" / "hil.py")
    for experiment in ("static_loading", "grasp_hold"):
        assert f"utrf.hil.{experiment}.report" in cli
        assert f"utrf.hil.{experiment}.analysis" not in cli  # one way to results: report.write
