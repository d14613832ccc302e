"""The candidates of a selection step fitted side by side on threads, and the model core run on
a thread of its own beside the rules engine, give the very report of one fitted after the other
(issue 25, the day at 1 Hz: :attr:`AttributionOptions.workers`)."""

from __future__ import annotations

import dataclasses
import json
import threading

import numpy as np
import pytest
from test_diagnose_worlds import make_world

import orbitcal.diagnose.api as api
import orbitcal.diagnose.model as model
from orbitcal.diagnose.api import diagnose_data
from orbitcal.diagnose.effects import CATALOGUE
from orbitcal.diagnose.options import DiagnosisOptions, ModelOptions


def _options(workers: int, engine: str = "rules") -> DiagnosisOptions:
    base = DiagnosisOptions(model=ModelOptions(engine=engine))
    return dataclasses.replace(
        base, attribution=dataclasses.replace(base.attribution, workers=workers)
    )


@pytest.mark.parametrize(
    ("effect", "attitude", "engine"),
    [
        ("magnetorquer", "tumbling", "rules"),
        ("none", "nadir", "rules"),
        ("temperature", "nadir", "model"),
    ],
)
def test_threads_do_not_change_the_report(
    effect: str, attitude: str, engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(api.os, "cpu_count", lambda: 2)  # the thread is used on any machine
    reports = []
    for workers in (1, 2):
        # a world of its own for each run: no design block is shared through the catalogue's
        # cache, so that the threaded run builds its own beside the model core
        data = make_world(effect, seed=5, attitude=attitude).data
        diag = diagnose_data(data, options=_options(workers, engine), rng=np.random.default_rng(0))
        reports.append(json.dumps(diag.report.to_json(), sort_keys=True))
    assert reports[0] == reports[1]
    assert json.loads(reports[0])["verdict"] == effect


def test_the_model_core_runs_beside_the_rules_engine_and_its_errors_reach_the_caller(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(api.os, "cpu_count", lambda: 2)
    threads: list[str] = []
    real = model.model_diagnosis

    def recorded(*args: object, **kwargs: object) -> object:
        threads.append(threading.current_thread().name)
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(model, "model_diagnosis", recorded)
    data = make_world("none", seed=5, attitude="nadir").data
    diagnose_data(data, options=_options(2), rng=np.random.default_rng(0))
    diagnose_data(data, options=_options(1), rng=np.random.default_rng(0))
    assert threads[0].startswith("orbitcal-model-core")
    assert threads[1] == threading.main_thread().name

    def failing(*args: object, **kwargs: object) -> object:
        raise ValueError("the model core failed")

    monkeypatch.setattr(model, "model_diagnosis", failing)
    for workers in (1, 2):
        with pytest.raises(ValueError, match="the model core failed"):
            diagnose_data(data, options=_options(workers), rng=np.random.default_rng(0))


def test_designs_built_on_two_threads_are_each_built_once_and_kept(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The catalogue's blocks are built two at a time before the model core starts: every
    effect's build runs once, on a builder thread, and what the engines ask for afterwards is
    the kept block (no entry of the cache is lost to the other thread)."""
    monkeypatch.setattr(api.os, "cpu_count", lambda: 2)
    builds: list[tuple[str, str]] = []
    for eff in CATALOGUE:

        def counted(data: object, train: object, _real: object = eff.build, _n: str = eff.name):
            builds.append((_n, threading.current_thread().name))
            return _real(data, train)  # type: ignore[operator]

        monkeypatch.setitem(eff.__dict__, "build", counted)
    data = make_world("magnetorquer", seed=5, attitude="tumbling").data
    diagnose_data(data, options=_options(2), rng=np.random.default_rng(0))
    names = [n for n, _ in builds]
    assert sorted(names) == sorted(e.name for e in CATALOGUE)
    assert {t.split("_")[0] for _, t in builds} == {"orbitcal-design"}
