"""The atlas's tables (docs/studies/*.csv) are plain CSV with a ``<stem>.meta.json``
sidecar holding what made them: the machine, the date and the settings (the defaults of
the scenes the study runs and the study's own constants) with their hash. A table whose
hash is not the code's was made with other settings than the code's: it fails here until
``eyemech study NAME`` makes it again."""

from __future__ import annotations

import csv
import dataclasses
import importlib
import json
from pathlib import Path

import pytest

from eyemech.problems.studies import studies
from eyemech.problems.studies._common import settings, sidecar

STUDIES = Path(__file__).resolve().parents[1] / "docs" / "studies"
TABLES = sorted(STUDIES.glob("*.csv"))
# tables made before a default they depend on changed (the difference is in the sidecar's
# settings against the code's): each is a case that fails once it is made again, so that
# it leaves this list
STALE: set[str] = set()
# study tables with a column that is a scene parameter's bare name, without its unit
# (`thickness`, not `thickness_mm`: studies/_common.with_units names them): each fails
# here once its study writes the unit and the table carries it (made again, or its header
# relabelled as the study now names it: the values do not change), so that it leaves this list
NO_UNITS: set[str] = set()
# study tables without a status per case: a case that failed there cannot be told from one
# that finished, and the study cannot exit 4 for it (issue 39). Each fails here once its
# study writes a status and the table carries it, so that it leaves this list
NO_STATUS: dict[str, str] = {}
# the tables of studies that measure where a method fails: what happened is their finding
# (an ``outcome`` column, studies/__init__.py), not a case that did not run
FINDINGS = {"newton_failure.csv"}


def _cases():
    for table in TABLES:
        marks = pytest.mark.xfail(strict=True, reason="made with other defaults: regenerate it") \
            if table.name in STALE else ()
        yield pytest.param(table, id=table.stem, marks=marks)


def differences(made: dict, now: dict) -> list[str]:
    out = []
    for scene, values in now["scene_defaults"].items():
        before = made.get("scene_defaults", {}).get(scene, {})
        out += [f"{scene}.{k}: {before.get(k, '(none)')!r} -> {v!r}" for k, v in values.items()
                if json.dumps(before.get(k), default=repr) != json.dumps(v, default=repr)]
    out += [f"{k} changed" for k, v in now["study_constants"].items()
            if json.dumps(made.get("study_constants", {}).get(k), sort_keys=True, default=repr)
            != json.dumps(v, sort_keys=True, default=repr)]
    return out


@pytest.mark.parametrize("table", list(_cases()))
def test_a_committed_table_was_made_with_the_codes_settings(table):
    assert not table.read_text().startswith("#"), "metadata belong in the sidecar"
    meta = json.loads(sidecar(table).read_text())
    assert meta["made"] and meta["quick"] is False
    if meta["study"] is None:  # a table of `eyemech sweep`: its grid is in its columns
        return
    module = studies()[meta["study"]].run.__module__
    importlib.import_module(module)
    now = settings(module)
    assert meta["settings_hash"] == now["settings_hash"], "\n".join(differences(meta, now)[:20])


def test_every_study_table_has_a_sidecar():
    assert TABLES and all(sidecar(t).exists() for t in TABLES)
    assert not {p.name for p in STUDIES.glob("*.meta.json")} - {sidecar(t).name for t in TABLES}


def _unit_cases():
    for table in TABLES:
        marks = pytest.mark.xfail(strict=True, reason="a parameter's column without its unit") \
            if table.name in NO_UNITS else ()
        yield pytest.param(table, id=table.stem, marks=marks)


@pytest.mark.parametrize("table", list(_unit_cases()))
def test_a_study_table_names_its_parameters_with_units(table):
    """A column that is a parameter of the scenes the study runs carries the parameter's
    unit in its name (issue 39: study CSVs had columns without units). `eyemech sweep`
    tables keep the grid's keys as typed."""
    from eyemech.problems import scenes

    meta = json.loads(sidecar(table).read_text())
    if meta["study"] is None:
        return
    used = meta.get("scene_defaults") or {}
    units: dict[str, str] = {}
    for name, scene in scenes().items():
        if used and name not in used:
            continue
        for field in dataclasses.fields(scene.parameters):
            units.setdefault(field.name, field.metadata.get("unit", ""))
    with open(table, newline="") as handle:
        header = next(csv.reader(handle))
    suffix = {"%": "percent"}
    bare = {c: units[c] for c in header if units.get(c)
            and not c.endswith("_" + suffix.get(units[c], units[c]))}
    assert not bare, f"columns without their unit: {bare}"


def _status_cases():
    for table in TABLES:
        marks = pytest.mark.xfail(strict=True, reason=NO_STATUS[table.name]) \
            if table.name in NO_STATUS else ()
        yield pytest.param(table, id=table.stem, marks=marks)


@pytest.mark.parametrize("table", list(_status_cases()))
def test_a_study_table_has_a_status_column(table):
    """A study table has a ``status`` column (ok, or what failed, per case), so that a failed
    case is told from a finished one and ``eyemech study`` exits 4 for it (issue 39: seven
    studies wrote none). `eyemech sweep` tables have theirs from the sweep."""
    meta = json.loads(sidecar(table).read_text())
    if meta["study"] is None or table.name in FINDINGS:
        return
    with open(table, newline="") as handle:
        header = next(csv.reader(handle))
    assert "status" in header, f"{table.name} has no status column: {header}"
