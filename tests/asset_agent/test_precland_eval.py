"""`bench/precland_eval.py`: closed-loop landings in process (seeded, deterministic)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.precland_eval import SCENARIOS, EkfVelocityError, main, run_trial


@pytest.mark.slow
def test_a_fused_landing_from_6m_seats_on_the_contacts():
    trial = run_trial(SCENARIOS["fused-6m"], seed=3)
    assert trial.landed and trial.error_m < 0.05 and trial.heading_deg < 2.0


@pytest.mark.slow
def test_ir_only_lands_near_and_no_sensor_lands_where_gnss_says():
    ir = [run_trial(SCENARIOS["ir"], seed=s) for s in range(3)]
    none = [run_trial(SCENARIOS["none"], seed=s) for s in range(3)]
    assert all(t.landed for t in ir + none)
    assert max(t.error_m for t in ir) < 0.3
    assert sum(t.error_m for t in none) > sum(t.error_m for t in ir)


def test_cli_prints_a_table_and_one_json_object_last(capsys):
    assert main(["--trials", "2", "--scenario", "ir", "--scenario", "none", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[0].startswith("scenario")
    result = json.loads(out[-1])
    assert set(result["scenarios"]) == {"ir", "none"}
    row = result["scenarios"]["ir"]
    assert row["landed"] == 2 and row["max_cm"] >= row["mean_cm"] > 0


def test_the_ekf_velocity_error_has_its_modelled_noise_and_slow_bias():
    err = EkfVelocityError(np.random.default_rng(5))
    e = np.array([err.step(0.01) for _ in range(60_000)])  # 600 s at 100 Hz
    total = float(np.hypot(err.NOISE_SIGMA, err.BIAS_SIGMA))
    assert 0.8 * total < float(e.std()) < 1.2 * total
    # averaged over 2 s the noise mostly averages out and the bias is left
    slow = e.reshape(-1, 200, 3).mean(axis=1)
    assert 0.6 * err.BIAS_SIGMA < float(slow.std()) < 1.4 * err.BIAS_SIGMA
