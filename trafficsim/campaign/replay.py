"""Re-simulate one encounter of a finished campaign alone and write a normal run folder.

Encounter ``k`` depends only on (campaign seed, ``k``) (:func:`trafficsim.campaign.generator.draw`),
and its ships' random streams are keyed by ``k`` whatever batch it runs in
(:mod:`trafficsim.campaign.runner`), so :func:`replay_encounter` rebuilds it with the same
streams, rules, policy, domain and step as the campaign (:func:`~.runner.prepare` on the one
encounter) and reproduces its rows exactly. The folder is the one ``trafficsim run`` writes
(:func:`trafficsim.run.record_run`, :func:`trafficsim.run.write_run`), so ``trafficsim
render`` and ``trafficsim explain`` work on it; its ``summary.json`` adds ``campaign_dir``,
``encounter`` and ``encounter_type``. It runs to the encounter's end in the campaign
(``end_s``: ``duration_s``, or later up to ``max_duration_s`` until every pair passed its
closest point), found by running the encounter once through the campaign's own loop.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from trafficsim.campaign.spec import CampaignSpec
from trafficsim.errors import InputError

#: record period of a replay unless asked otherwise (rounded to whole steps)
RECORD_EVERY_S = 5.0


def campaign_spec(campaign_dir: str | Path) -> CampaignSpec:
    """The spec a campaign folder was run with, checked to be unchanged since (with the ship
    and rules files it names).

    Raises:
        InputError: not a campaign folder, the spec file gone, or it or a file it names
            changed since the run.
    """
    from trafficsim.campaign.execute import _spec_hash, inputs_digest
    from trafficsim.campaign.spec import load_spec

    folder = Path(campaign_dir)
    manifest = folder / "campaign.json"
    if not folder.is_dir():
        raise InputError("no such folder (the output folder of 'trafficsim "
                         "campaign' was expected)", path=str(folder))
    if not manifest.is_file():
        raise InputError("no campaign.json here (the output folder of 'trafficsim "
                         "campaign' was expected)", path=str(folder))
    try:
        info = json.loads(manifest.read_text())
    except (OSError, ValueError) as err:
        raise InputError(f"unreadable ({err})", path=str(manifest)) from None
    if not isinstance(info, dict):
        raise InputError(f"unreadable (expected a JSON object, got {type(info).__name__})",
                         path=str(manifest))
    for key, what in (("spec", "the path of the campaign's spec"),
                      ("spec_sha256", "the SHA-256 of the campaign's spec")):
        if key not in info:
            raise InputError(f"missing key (expected {what})", path=str(manifest), key=key)
        if not isinstance(info[key], str) or not info[key]:
            raise InputError(f"expected {what} as text, got {info[key]!r}", path=str(manifest),
                             key=key)
    spec_path, digest = Path(info["spec"]), info["spec_sha256"]
    if not spec_path.is_file():
        raise InputError(f"the campaign's spec {spec_path} is gone; a replay needs "
                         "it", path=str(manifest))
    if _spec_hash(spec_path) != digest:
        raise InputError(f"changed since the campaign in {folder} ran; a replay "
                         "would not reproduce it (restore the spec, or run the campaign "
                         "again)", path=str(spec_path))
    spec = load_spec(spec_path)
    if "inputs_sha256" in info and inputs_digest(spec) != info["inputs_sha256"]:
        raise InputError(f"a ship or rules file this spec names changed since the campaign "
                         f"in {folder} ran; a replay would not reproduce it (restore it, or run "
                         "the campaign again)", path=str(spec_path))
    return spec


def replay_encounter(campaign_dir: str | Path, encounter: int, out_dir: str | Path,
                     record_every_s: float | None = None, on_record: Any = None
                     ) -> dict[str, Any]:
    """Simulate encounter ``encounter`` of the campaign in ``campaign_dir`` and write its run
    folder to ``out_dir``; return the summary. ``on_record`` as for
    :func:`trafficsim.run.record_run`.

    Raises:
        InputError: see :func:`campaign_spec`; ``out_dir`` holding a campaign's results; an
            encounter index outside the campaign; a record period that is not a positive
            multiple of the campaign's step, or longer than its ``duration_s``.
    """
    from trafficsim.campaign.runner import prepare, run_chunk
    from trafficsim.folders import refuse_other_results
    from trafficsim.run import raise_if_diverged, record_run, run_summary, write_run

    spec = campaign_spec(campaign_dir)
    refuse_other_results(Path(out_dir), "run", "a replay (a run folder)")
    if not 0 <= encounter < spec.n_encounters:
        raise InputError(f"expected an encounter index 0 .. {spec.n_encounters - 1}, got "
                         f"{encounter}", key="--encounter")
    every_s = RECORD_EVERY_S if record_every_s is None else record_every_s
    every = round(every_s / spec.dt_s) if math.isfinite(every_s) else 0
    if every < 1 or abs(every * spec.dt_s - every_s) > 1e-9 * every_s:
        if record_every_s is not None:
            raise InputError(f"expected a whole multiple of the campaign's step "
                             f"({spec.dt_s:g} s), got {record_every_s:g}",
                             key="--record-every-s")
        every = max(1, every)
    if record_every_s is not None and every * spec.dt_s > spec.duration_s * (1.0 + 1e-9):
        raise InputError(f"must not exceed the encounter's duration ({spec.duration_s:g} s, "
                         f"duration_s of {spec.path}), got {record_every_s:g} (only the start "
                         "would be recorded)", key="--record-every-s")
    end_s = spec.duration_s
    if spec.longest_s > spec.duration_s:  # where the campaign took its figures
        end_s = float(run_chunk(spec, encounter, encounter + 1)["end_s"][0])
    encounters, sim = prepare(spec, encounter, encounter + 1)
    if sim.decider is not None:
        sim.decider.record = True  # decisions.parquet (recording changes nothing else)
    n_steps = round(end_s / spec.dt_s)
    rec, wall = record_run(sim, n_steps, every, on_record)
    header = {"scenario": f"{spec.name} encounter {encounter}",
              "scenario_file": str(spec.path), "seed": spec.seed,
              "duration_s": end_s, "dt_s": spec.dt_s,
              "campaign_dir": str(Path(campaign_dir).resolve()), "encounter": encounter,
              "encounter_type": encounters[0].kind}
    summary = run_summary(header, sim, n_steps, wall, max(sim.step_index - 1, 1),
                          every * spec.dt_s, spec.domain)
    write_run(Path(out_dir), rec, sim, summary)
    raise_if_diverged(sim, Path(out_dir))
    return summary
