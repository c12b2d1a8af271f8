"""An encounter replayed alone is the encounter the campaign ran: the same smallest range at
the same time for every pair, bit for bit, in a run folder the other commands read."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim.campaign.execute import run_campaign
from trafficsim.campaign.replay import replay_encounter
from trafficsim.cli import main
from trafficsim.colregs.explain import explain_run
from trafficsim.errors import InputError
from trafficsim.units import NM

SENSORS = ("sensors: {gnss_sigma_m: [1, 5], compass_sigma_deg: [0.1, 0.5]}\n"
           "encounter_types: {crossing_give_way: 1, head_on: 1, multi: 1}\nmulti_ships: [3, 3]")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from tests.campaign.conftest import SMALL

    folder = tmp_path_factory.mktemp("campaign")
    spec = folder / "spec.yaml"
    spec.write_text(SMALL.format(n=4, chunk=3, duration=600, extra=SENSORS, rogue=0.3))
    run_campaign(spec, folder / "out", workers=1, progress=False)
    return spec, folder / "out"


def test_replay_reproduces_every_pair_of_the_campaign_exactly(campaign, tmp_path):
    _, out = campaign
    rows = pq.read_table(out / "encounters.parquet").to_pydict()
    for k in range(4):
        summary = replay_encounter(out, k, tmp_path / f"e{k}")
        mine = [i for i, e in enumerate(rows["encounter"]) if e == k]
        assert summary["encounter"] == k and summary["n_ships"] >= 2
        assert summary["encounter_type"] == rows["encounter_type"][mine[0]]
        assert len(summary["pairs"]) == len(mine)
        for i, pair in zip(mine, summary["pairs"], strict=True):
            assert (pair["ship_a"], pair["ship_b"]) == (rows["ship_i"][i], rows["ship_j"][i])
            assert pair["min_range_m"] == rows["min_range_m"][i]  # exactly
            assert pair["t_min_range_s"] == rows["t_cpa_s"][i]
            assert pair["collision"] == rows["collision"][i]
            assert pair["domain_violation"] == rows["domain_violation"][i]
            assert pair["dcpa_m"] == pytest.approx(rows["dcpa0_nm"][i] * NM, rel=1e-12)


def test_a_replay_is_a_run_folder(campaign, tmp_path):
    _, out = campaign
    replay_encounter(out, 1, tmp_path / "r", record_every_s=10.0)
    for name in ("trajectories.parquet", "tracks.parquet", "decisions.parquet",
                 "summary.json"):
        assert (tmp_path / "r" / name).is_file(), name
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["record_every_s"] == 10.0 and summary["campaign_dir"] == str(out.resolve())
    table = pq.read_table(tmp_path / "r" / "trajectories.parquet")
    assert table.num_rows == summary["n_ships"] * (600 // 10 + 1)
    assert np.all(np.diff(np.unique(table.column("t_s").to_numpy())) == 10.0)
    assert "own: decisions that changed something" in explain_run(tmp_path / "r", "own")


def test_replay_errors(campaign, tmp_path, capsys):
    spec, out = campaign
    with pytest.raises(InputError, match=r"expected an encounter index 0 \.\. 3, got 4"):
        replay_encounter(out, 4, tmp_path / "x")
    with pytest.raises(InputError, match="whole multiple of the campaign's step"):
        replay_encounter(out, 0, tmp_path / "x", record_every_s=2.5)
    with pytest.raises(InputError, match=r"no campaign\.json here"):
        replay_encounter(tmp_path, 0, tmp_path / "x")
    assert main(["replay", str(tmp_path / "none"), "--encounter", "0", "--out",
                 str(tmp_path / "x")]) == 2
    assert "no such folder" in capsys.readouterr().err
    original = spec.read_text()
    try:
        spec.write_text(original.replace("seed: 11", "seed: 12"))
        with pytest.raises(InputError, match="changed since the campaign"):
            replay_encounter(out, 0, tmp_path / "x")
    finally:
        spec.write_text(original)


def test_replay_command_prints_the_pairs(campaign, tmp_path, capsys):
    _, out = campaign
    assert main(["replay", str(out), "--encounter", "2", "--out", str(tmp_path / "r")]) == 0
    text = capsys.readouterr().out
    assert text.startswith("small encounter 2 (") and "own - ship1: min range" in text
