"""Reproduction of Wang et al. (2020): Table 1, LM epochs, ground and on-orbit errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orbitcal.cli import main
from orbitcal.reproduce import wang2020 as w20


@pytest.fixture(scope="module")
def result() -> w20.Wang2020Result:
    return w20.reproduce_wang2020()


def test_constants_are_the_papers_and_agree_with_the_sensor_module() -> None:
    from orbitcal import sensor

    np.testing.assert_array_equal(w20.A_GROUND, np.array(sensor.WANG2020_GROUND_A))
    np.testing.assert_array_equal(w20.B0_GROUND_NT, np.array(sensor.WANG2020_GROUND_B0_NT))
    np.testing.assert_array_equal(w20.A_ORBIT, np.array(sensor.WANG2020_ORBIT_A))
    np.testing.assert_array_equal(w20.B0_ORBIT_NT, np.array(sensor.WANG2020_ORBIT_B0_NT))
    # eq. 16 at t = π/2: 4000 + 100·[1, 0, −1]
    np.testing.assert_allclose(w20.true_field_nt(np.array([np.pi / 2]))[0], [4100, 4000, 3900])


def test_table1_regression_coefficients(result: w20.Wang2020Result) -> None:
    r = dict(result.table1)
    assert sorted(r) == [2, 3, 4, 5, 6, 7]
    for h in (3, 4, 5, 6, 7):
        assert r[h] >= 0.999, (h, r[h])  # paper: 0.9999 (ours is limited by the 2 nT noise)
    assert r[2] < 0.9  # paper: 0.82121; a 2-node bottleneck on a 3-D field: √(2/3) ≈ 0.816
    assert abs(r[2] - 0.82121) < 0.03
    # on eq. 16 itself (a planar field) two nodes are enough: reported, not hidden
    assert dict(result.table1_eq16)[2] > 0.999


def test_lm_epochs_and_errors(result: w20.Wang2020Result) -> None:
    assert 1 <= result.lm_epochs_to_mse_1e3 <= 26  # paper: 26 epochs
    assert result.ground_max_error_nt < 10.0  # paper: < 10 nT
    assert 20.0 < result.max_error_without_retraining_nt < 40.0  # paper: ~30 nT
    assert result.max_error_after_retraining_nt < 10.0  # paper: < 10 nT
    assert result.n_retrainings >= 10


def test_cli_json_has_exactly_the_section_6_keys(
    result: w20.Wang2020Result, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(w20, "reproduce_wang2020", lambda **_: result)
    assert main(["reproduce", "wang2020", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) == {"table1", "lm_epochs_to_mse_1e-3", "ground_max_error_nt", "orbit_change"}
    assert set(doc["orbit_change"]) == {
        "max_error_without_retraining_nt",
        "max_error_after_retraining_nt",
    }
    assert [set(row) for row in doc["table1"]] == [{"hidden_nodes", "regression_coefficient"}] * 6
    assert [row["hidden_nodes"] for row in doc["table1"]] == [2, 3, 4, 5, 6, 7]
    assert isinstance(doc["lm_epochs_to_mse_1e-3"], int)
    assert doc == result.to_json()
    assert main(["reproduce", "wang2020"]) == 0
    table = capsys.readouterr().out
    assert "0.82121" in table and "paper" in table and "orbitcal" in table
