"""The dataset card (``README.md``) of a LeRobot export, shaped as lerobot's ``create_lerobot_dataset_card``.

The Hugging Face Hub reads the YAML header: tags ``LeRobot`` (and ``tactile``), the ``robotics`` task
category, the ``default`` config over ``data/*/*.parquet``; the body says where the data came from,
what each column is, and shows ``meta/info.json`` as lerobot's card does.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["card"]


def _episodes(rows: list[dict[str, Any]]) -> str:
    lines = ["| episode | task | from (UTC, ns) | to | frames |", "|---|---|---|---|---|"]
    for r in rows[:50]:
        lines.append(f"| {r['episode']} | {r['task']} | {r['start_ns']} | {r['end_ns']} | {r['frames']} |")
    if len(rows) > 50:
        lines.append(f"| ... | {len(rows) - 50} more in meta/wott.json | | | |")
    return "\n".join(lines)


def card(info: dict[str, Any], provenance: dict[str, Any]) -> str:
    """The card's text."""
    features = info["features"]
    has_action = "action" in features
    rows = [
        f"| `{k}` | {v['dtype']} | {tuple(v['shape'])} | {(v.get('info') or {}).get('unit', '')} |"
        for k, v in features.items()
    ]
    use = (
        "`action` is the recorded property " + f"`{provenance['action']}`, held at each frame: the dataset "
        "trains a policy (ACT, Diffusion) mapping the observations to it."
        if has_action
        else "There is no `action` column (no `--action` was given): the dataset serves what needs "
        "observations only (tactile representation learning, touch classification with the `action` "
        "codes of each device, world models, visualisation), not behaviour cloning."
    )
    header = "\n".join(
        [
            "---",
            "license: other",
            "tags:",
            "- LeRobot",
            "- tactile",
            "- wott-hub",
            "task_categories:",
            "- robotics",
            "configs:",
            "- config_name: default",
            "  data_files: data/*/*.parquet",
            "---",
        ]
    )
    return f"""{header}

This dataset was exported from a wott-hub history (tactile sensors recorded by a Web of Things gateway) by
`wott-hub history export --format
lerobot` in the [LeRobot](https://github.com/huggingface/lerobot) dataset format {info["codebase_version"]}.

## Dataset Description

{len(provenance["things"])} recorded Thing(s) ({", ".join(provenance["things"])}) resampled onto one grid of
{info["fps"]} frames per second by zero-order hold: each value is the last one recorded at or before its
frame's time, never a later one; `age.<id>` gives, per frame, how old each held sample is (seconds, -1:
none yet, the device's rest value stands). {use}

- **Episodes:** {info["total_episodes"]}, {info["total_frames"]} frames, {info["total_tasks"]} task(s)
- **Source:** {provenance["database"]}
- **Exported:** {provenance["exported"]}
- **License:** [More Information Needed]

{_episodes(provenance["episodes"])}

## Dataset Structure

| feature | dtype | shape | unit |
|---|---|---|---|
{chr(10).join(rows)}

[meta/info.json](meta/info.json):
```json
{json.dumps(info, indent=4)}
```
"""
