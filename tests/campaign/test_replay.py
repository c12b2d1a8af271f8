"""An encounter replayed alone is the encounter the campaign ran: the same smallest range at
the same time for every pair, bit for bit, in a run folder the other commands read."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from trafficsim.campaign.execute import run_campaign
from trafficsim.campaign.replay import replay_encounter
from trafficsim.campaign.runner import run_chunk
from trafficsim.campaign.spec import load_spec
from trafficsim.cli import main
from trafficsim.colregs.explain import explain_run
from trafficsim.errors import InputError
from trafficsim.units import NM

SENSORS = ("sensors: {gnss_sigma_m: [1, 5], compass_sigma_deg: [0.1, 0.5]}\n"
           "encounter_types: {crossing_give_way: 1, head_on: 1, multi: 1}\nmulti_ships: [3, 3]\n"
           "tcpa_min: [5, 10]")


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


# --------------------------------------------------------------------------------------------
# replays of a campaign with weather and rogues, whatever the encounter's place in its chunk
# --------------------------------------------------------------------------------------------

WEATHER = ("sensors: {gnss_sigma_m: [1, 5], compass_sigma_deg: [0.1, 0.5]}\n"
           "current_kn: [0.5, 1.5]\nwind_mps: [5, 15]\ndcpa_nm: [0.0, 0.3]\ntcpa_min: [3, 4]\n"
           "encounter_types: {head_on: 1, crossing_give_way: 1, overtaking: 1, multi: 1}\n"
           "multi_ships: [3, 4]")


@pytest.fixture(scope="module")
def windy(tmp_path_factory):
    """Five encounters in chunks of two (0-1, 2-3, 4 alone) with current, wind, instruments
    and rogues: every random stream of a ship in use."""
    from tests.campaign.conftest import SMALL

    folder = tmp_path_factory.mktemp("windy")
    spec = folder / "spec.yaml"
    spec.write_text(SMALL.format(n=5, chunk=2, duration=300, extra=WEATHER, rogue=0.4))
    run_campaign(spec, folder / "out", workers=1, progress=False)
    return spec, folder / "out"


@pytest.mark.parametrize("k", [0, 1, 3, 4])
def test_replay_reproduces_its_rows_from_any_place_in_its_chunk(windy, tmp_path, k):
    """Encounter ``k`` replayed alone (first or second of its chunk, or alone in the short last
    chunk) gives exactly the campaign's rows: smallest range and its time, collision, domain,
    start DCPA and TCPA of every pair, and the same blind spots (pair and first role)."""
    _, out = windy
    rows = pq.read_table(out / "encounters.parquet").to_pydict()
    summary = replay_encounter(out, k, tmp_path / "r")
    mine = [i for i, e in enumerate(rows["encounter"]) if e == k]
    assert len(summary["pairs"]) == len(mine) > 0
    n = summary["n_ships"]
    assert len(mine) == n * (n - 1) // 2
    for i, pair in zip(mine, summary["pairs"], strict=True):
        assert (pair["ship_a"], pair["ship_b"]) == (rows["ship_i"][i], rows["ship_j"][i])
        assert pair["min_range_m"] == rows["min_range_m"][i]
        assert pair["t_min_range_s"] == rows["t_cpa_s"][i]
        assert pair["collision"] == rows["collision"][i]
        assert pair["domain_violation"] == rows["domain_violation"][i]
        assert pair["tcpa_s"] == pytest.approx(rows["tcpa0_min"][i] * 60.0, rel=1e-12)
    first_role: dict[frozenset, str] = {}
    for spot in summary["blind_spots"]:
        first_role.setdefault(frozenset((spot["ship"], spot["other"])), spot["role"])
    from_rows = {frozenset((rows["ship_i"][i], rows["ship_j"][i])): rows["blind_spot_role"][i]
                 for i in mine if rows["blind_spot"][i]}
    assert first_role == from_rows
    assert summary["encounter_type"] == rows["encounter_type"][mine[0]]


def test_two_replays_of_one_encounter_are_identical(windy, tmp_path):
    """A replay is a function of (campaign seed, index): run twice, its trajectories (every
    recorded state, estimate and instrument reading) are the same to the bit."""
    _, out = windy
    replay_encounter(out, 2, tmp_path / "a")
    replay_encounter(out, 2, tmp_path / "b")
    a = pq.read_table(tmp_path / "a" / "trajectories.parquet")
    b = pq.read_table(tmp_path / "b" / "trajectories.parquet")
    assert a.column_names == b.column_names and a.num_rows == b.num_rows > 0
    for name in a.column_names:
        x, y = a.column(name).to_numpy(zero_copy_only=False), b.column(name).to_numpy(
            zero_copy_only=False)
        if x.dtype.kind == "f":
            np.testing.assert_array_equal(x, y, err_msg=name)
        else:
            assert x.tolist() == y.tolist(), name


def test_replay_ignores_the_chunking_of_the_campaign(windy, tmp_path):
    """The replay of encounter 3 equals the row of a campaign cut into chunks of one (encounter
    3 then simulated alone, not beside encounter 2)."""
    from tests.campaign.conftest import SMALL

    spec = tmp_path / "ones.yaml"
    spec.write_text(SMALL.format(n=5, chunk=1, duration=300, extra=WEATHER, rogue=0.4))
    row = run_chunk(load_spec(spec), 3, 4)
    summary = replay_encounter(windy[1], 3, tmp_path / "r")
    assert [p["min_range_m"] for p in summary["pairs"]] == list(row["min_range_m"])
    assert [p["t_min_range_s"] for p in summary["pairs"]] == list(row["t_cpa_s"])


def _small_campaign(tmp_path, dt_s: float, name: str = "c"):
    from tests.campaign.conftest import SMALL

    spec = tmp_path / f"{name}.yaml"
    spec.write_text(SMALL.format(n=1, chunk=1, duration=240, rogue=0.0,
                                 extra=f"dt_s: {dt_s}\npolicy: no_avoidance\ntcpa_min: [2, 4]"))
    run_campaign(spec, tmp_path / name, workers=1, progress=False)
    return spec, tmp_path / name


def test_the_default_record_period_is_five_seconds_rounded_to_whole_steps(tmp_path):
    """With 2 s steps the default 5 s is 2.5 steps, rounded (half to even) to 2 steps: records
    every 4 s, 240 / 4 + 1 = 61 per ship. An explicit 3 s (1.5 steps) is refused; 6 s is 3
    steps and kept."""
    _, out = _small_campaign(tmp_path, 2.0)
    summary = replay_encounter(out, 0, tmp_path / "r")
    assert summary["record_every_s"] == 4.0
    times = np.unique(pq.read_table(tmp_path / "r" / "trajectories.parquet")
                      .column("t_s").to_numpy())
    np.testing.assert_array_equal(times, np.arange(0.0, 241.0, 4.0))
    with pytest.raises(InputError, match=r"whole multiple of the campaign's step \(2 s\), got 3"):
        replay_encounter(out, 0, tmp_path / "x", record_every_s=3.0)
    assert replay_encounter(out, 0, tmp_path / "y", record_every_s=6.0)["record_every_s"] == 6.0


@pytest.mark.parametrize("period", [0.0, -5.0])
def test_a_record_period_not_positive_is_refused(campaign, tmp_path, period):
    """Zero or negative record periods are no positive multiple of the step."""
    with pytest.raises(InputError) as info:
        replay_encounter(campaign[1], 0, tmp_path / "x", record_every_s=period)
    assert info.value.key == "--record-every-s"


@pytest.mark.parametrize("period", [float("nan"), float("inf")])
def test_a_record_period_not_finite_is_an_input_error(campaign, tmp_path, period):
    """The docstring promises an InputError for a record period that is not a positive multiple
    of the step; NaN and infinity are not (the command line refuses them, the API must too)."""
    with pytest.raises(InputError):
        replay_encounter(campaign[1], 0, tmp_path / "x", record_every_s=period)


def test_a_negative_encounter_index_is_refused(campaign, tmp_path):
    """Index -1 would be Python's last element: it is outside ``0 .. n - 1`` and refused."""
    with pytest.raises(InputError, match=r"0 \.\. 3, got -1") as info:
        replay_encounter(campaign[1], -1, tmp_path / "x")
    assert info.value.key == "--encounter"
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(("manifest", "message", "key"), [
    ("{broken", "unreadable", None),
    ("[]", "unreadable (expected a JSON object, got list)", None),
    ('{"spec": "x.yaml"}', "missing key (expected the SHA-256 of the campaign's spec)",
     "spec_sha256"),
    ('{"spec_sha256": "ab"}', "missing key (expected the path of the campaign's spec)", "spec"),
    ('{"spec": 3, "spec_sha256": "ab"}', "expected the path of the campaign's spec as text, "
     "got 3", "spec"),
])
def test_a_damaged_manifest_is_named(tmp_path, manifest, message, key):
    """``campaign.json`` that is not JSON, not an object, or lacks a key it must hold or holds
    it as no text: an InputError naming the manifest and the key (not "unreadable ('spec')")."""
    (tmp_path / "campaign.json").write_text(manifest)
    with pytest.raises(InputError) as info:
        replay_encounter(tmp_path, 0, tmp_path / "x")
    assert info.value.message.startswith(message), info.value.message
    assert (info.value.path, info.value.key) == (str(tmp_path / "campaign.json"), key)


def test_a_record_period_beyond_the_encounter_is_refused(campaign, tmp_path, capsys):
    """A record period longer than the campaign's 600 s encounters would record t = 0 alone
    (a scenario file refuses it as well): exit 2 naming the flag and the duration, no folder
    made; the whole duration is accepted (t = 0 and 600 s)."""
    from tests.conftest import error_line

    spec, out = campaign
    line = error_line(capsys, ["replay", out, "--encounter", "1", "--record-every-s", "100000",
                               "--out", tmp_path / "rp"])
    assert line == ("trafficsim: error: --record-every-s: must not exceed the encounter's "
                    f"duration (600 s, duration_s of {spec}), got 100000 (only the start would "
                    "be recorded)")
    assert not (tmp_path / "rp").exists()
    replay_encounter(out, 1, tmp_path / "whole", record_every_s=600.0)
    times = pq.read_table(tmp_path / "whole" / "trajectories.parquet").column("t_s")
    assert sorted(set(times.to_pylist())) == [0.0, 600.0]


def test_a_spec_gone_or_a_file_given_is_refused(tmp_path):
    """A campaign whose spec was deleted cannot be replayed (InputError naming it); a file
    given for the folder is "no such folder"."""
    spec, out = _small_campaign(tmp_path, 1.0)
    spec.unlink()
    with pytest.raises(InputError, match="is gone"):
        replay_encounter(out, 0, tmp_path / "x")
    with pytest.raises(InputError, match="no such folder"):
        replay_encounter(out / "campaign.json", 0, tmp_path / "x")


def test_a_replay_runs_to_the_encounters_end_in_the_campaign(tmp_path):
    """With ``max_duration_s`` encounters end when their pairs have passed: each replay runs
    to its encounter's ``end_s`` (some past ``duration_s``) and gives its rows exactly."""
    from tests.campaign.conftest import SMALL

    spec = tmp_path / "on.yaml"
    spec.write_text(SMALL.format(n=6, chunk=6, duration=720, rogue=0.0, extra=(
        "max_duration_s: 1800\ntcpa_min: [8, 12]\nencounter_types: {overtaking: 1, "
        "crossing_give_way: 1, head_on: 1, multi: 1}")))
    run_campaign(spec, tmp_path / "out", workers=1, progress=False)
    rows = run_chunk(load_spec(spec), 0, 6)
    enc = np.asarray(rows["encounter"])
    end = np.asarray(rows["end_s"])
    assert (end > 720.0).any()
    for k in [*np.unique(enc[end > 720.0]).tolist(), int(enc[end == 720.0][0])]:
        summary = replay_encounter(tmp_path / "out", k, tmp_path / f"r{k}")
        mine = enc == k
        assert summary["duration_s"] == end[mine][0]
        assert [p["min_range_m"] for p in summary["pairs"]] == list(
            np.asarray(rows["min_range_m"])[mine])
        assert [p["t_min_range_s"] for p in summary["pairs"]] == list(
            np.asarray(rows["t_cpa_s"])[mine])
