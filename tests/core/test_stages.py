# SPDX-License-Identifier: LGPL-2.1-or-later
"""The stage table: ``core.pipeline.STAGES`` as docs/DESIGN.md describes it, typed results."""
import dataclasses
import os
import re

import pytest

from core import types
from core.pipeline import CORE_STAGES, STAGES

DESIGN = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "DESIGN.md")


def _design_rows():
    """{stage: (module path, function, result type, report key)} from DESIGN.md's table."""
    with open(DESIGN, encoding="utf-8") as handle:
        text = handle.read()
    rows = {}
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) != 6 or not cells[0].startswith("`"):
            continue
        stage = cells[0].strip("`")
        module = re.match(r"`([^`]+)` \(`([^`]+)`", cells[1])
        result = re.match(r"`([^`]+)`", cells[3])
        rows[stage] = (module.group(1), module.group(2), result.group(1), cells[5].strip("`"))
    return rows


def test_design_md_starts_with_the_stage_table_of_the_runner():
    with open(DESIGN, encoding="utf-8") as handle:
        head = handle.read(2000)
    assert "## The stages" in head, "docs/DESIGN.md starts with the stage table"
    rows = _design_rows()
    assert [name for name in rows if name in CORE_STAGES] == list(CORE_STAGES)
    for stage in STAGES:
        module, function, result, key = rows[stage.name]
        assert module == stage.run.__module__.replace(".", "/") + ".py", stage.name
        assert function == stage.run.__name__, stage.name
        assert key == stage.report_key, stage.name
        assert dataclasses.is_dataclass(getattr(types, result, None)), result


@pytest.mark.parametrize("stage", STAGES, ids=lambda s: s.name)
def test_every_stage_reads_only_declared_results_and_returns_its_own_type(stage):
    fields = {f.name: f for f in dataclasses.fields(types.PipelineState)}
    assert stage.name in fields, "every stage has its field in PipelineState"
    assert set(stage.inputs) <= set(fields)
    # inputs come from earlier stages (or the source): the table is in run order
    earlier = {"source"} | set(CORE_STAGES[:CORE_STAGES.index(stage.name)])
    assert set(stage.inputs) <= earlier
    names = {f.name for f in dataclasses.fields(getattr(types, _design_rows()[stage.name][2]))}
    assert {"report", "message"} <= names


@pytest.mark.slow
def test_a_run_holds_one_result_of_the_documented_type_per_stage(tmp_path):
    import trimesh

    from core.pipeline import reconstruct

    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=(10.0, 20.0, 30.0)).export(path)
    result = reconstruct(path, {"fit_iterations": 2})
    assert result.failed is None, result.report["stages"]
    rows = _design_rows()
    for stage in STAGES:
        value = getattr(result.state, stage.name)
        assert type(value).__name__ == rows[stage.name][2], stage.name
        assert result.report[stage.report_key] == value.report, stage.name
        assert result.report["stages"][stage.name] == {
            "status": "ok", "message": value.message,
            "seconds": result.report["stages"][stage.name]["seconds"],
            "cpu_seconds": result.report["stages"][stage.name]["cpu_seconds"],
            "peak_memory_mb": result.report["stages"][stage.name]["peak_memory_mb"]}
    assert set(result.report) == {"parameters", "stages", "total_seconds", "peak_memory_mb"} | {
        stage.report_key for stage in STAGES}
