"""CI regression: the small sweep configs/sweeps/regression.yaml against its stored baselines
(configs/sweeps/regression_expected.yaml, whose header states the tolerances). A change that
degrades accuracy, topological consistency or iteration counts fails here; timing is left to
benchmarks/."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from fccgrb_cli.report import collect
from fccgrb_cli.sweep import load_sweep, run_sweep

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "sweeps" / "regression.yaml"
EXPECTED = yaml.safe_load((ROOT / "configs" / "sweeps" / "regression_expected.yaml").read_text())


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> dict[str, dict[str, float]]:
    out = tmp_path_factory.mktemp("regression") / "regression.h5"
    run_sweep(load_sweep(CONFIG), out, workers=1)
    _, rows = collect(out)
    return {f"{r.family} {r.variant} pts={r.points or '-'} tol={r.tol:g} {r.level}": r.values
            for r in rows}


def test_every_baseline_row_was_measured(measured: dict) -> None:
    assert set(EXPECTED["rows"]) == set(measured)


@pytest.mark.parametrize("key", sorted(EXPECTED["rows"]))
def test_row_holds_its_baseline(measured: dict, key: str) -> None:
    base, now = EXPECTED["rows"][key], measured[key]
    exact = key.endswith("P0") or key.split()[0] in ("KA", "CNO", "MO")
    assert now["failed frames"] == 0
    assert now["iterations/frame"] <= base["iterations"] + 0.5
    if exact:
        assert now["max |Φ_top|"] <= 1e-9
    else:
        assert 0.8 * base["phi_top_max"] <= now["max |Φ_top|"] <= 1.25 * base["phi_top_max"]
    if key.endswith("P0"):
        assert now["mean ED (mm)"] <= 1e-3
    else:
        assert now["mean ED (mm)"] <= 1.05 * base["mean_ed_mm"]


def test_weighting_keeps_the_paper_s_order(measured: dict) -> None:
    """WLS at least 10× lower topological violation than LS at 30 mm (the paper: ~60×)."""
    ls = measured["NRM LS pts=8 tol=1e-10 P30"]["max |Φ_top|"]
    wls = measured["NRM WLS pts=8 tol=1e-10 P30"]["max |Φ_top|"]
    assert ls >= 10 * wls
