"""Multi-agent views of the eel: every interior node an agent (PettingZoo's parallel API).

``soft_snake_gym.multiagent.eel_segments_v0`` is the PettingZoo env (``parallel_env()``,
``env()``; needs ``pip install 'soft_snake_gym[multiagent]'``); :class:`SegmentsEnv` is the same
team as one Gymnasium env, registered as ``SoftEelSegments-v0`` for ``evaluate``, ``compare`` and
``train``; :mod:`.policies` runs the baselines and shared local policies on it.
"""

from soft_snake_gym.multiagent.segments import (
    SEGMENT_KEYS,
    SegmentLayout,
    SegmentsEnv,
    agent_ids,
    local_power,
    node_index,
    split_kwargs,
)

__all__ = [
    "SEGMENT_KEYS",
    "SegmentLayout",
    "SegmentsEnv",
    "agent_ids",
    "local_power",
    "node_index",
    "split_kwargs",
]
