"""An unknown flag gets the sub-command's usage and the flag meant, not the top-level usage."""

from __future__ import annotations

import pytest

from orbitcal.cli import main


def test_a_misspelt_flag_names_the_flag_meant(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "t.csv", "--tle", "x.tle", "--methdo", "linear", "--out", "c.json"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: orbitcal calibrate ")  # the sub-command's usage
    assert "usage: orbitcal [-h]" not in err
    assert "--methdo: did you mean --method?" in err.splitlines()[-1]


def test_a_flag_nothing_resembles_is_only_named(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["truth", "t.csv", "--tle", "x.tle", "--out", "o.csv", "--zzzzzz"])
    last = capsys.readouterr().err.splitlines()[-1]
    assert last == "orbitcal truth: error: unrecognized arguments: --zzzzzz"
