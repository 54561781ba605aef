"""Random streams of the sea and the links: one per formation, separate from the initial state's.

Randomness comes only from these streams, one set per formation, seeded at
reset by the front end (``channel_streams``): a generator of uniforms for
the channel (loss, delays, link failures) and one of normals for the sensor
noise, both independent of ``np.random.default_rng(seed)``, the initial-state
stream of the same seed. They are served in blocks (``BlockStream``: one
generator call per formation every few steps), which changes the cost, not
the numbers: a formation sees the same sequence whatever the batch size.
"""

from __future__ import annotations

import numpy as np

from marine_formation_env.errors import check_seed

__all__ = ["CHANNEL_STREAM_KEY", "BlockStream", "channel_streams"]

#: Spawn key that separates the channel stream from the initial-state stream of one seed.
CHANNEL_STREAM_KEY = 0x43484E


def channel_streams(seed: int | None) -> tuple[np.random.Generator, np.random.Generator]:
    """The channel's generators for a reset seed: ``(uniforms, normals)``.

    Both are independent of ``np.random.default_rng(seed)`` (the initial-state
    stream of the same seed) and of each other. ``None`` draws fresh entropy.
    """
    root = np.random.SeedSequence(check_seed(seed, "channel seed"), spawn_key=(CHANNEL_STREAM_KEY,))
    uniform, normal = root.spawn(2)
    return np.random.default_rng(uniform), np.random.default_rng(normal)


class BlockStream:
    """Per-formation random streams, drawn a block of rows at a time.

    Row ``k`` of formation ``b`` is the ``k``-th ``width`` numbers of its
    generator, whatever the block size: a generator's ``random`` and
    ``standard_normal`` give the same sequence in one call or in many. Blocks
    only save generator calls (one per formation every ``block`` rows). The
    block size keeps the buffer under ``max_floats`` numbers.

    Args:
        num_envs: formations ``B``.
        width: numbers per row.
        normal: standard normals instead of uniforms in [0, 1).
        max_floats: buffer budget; ``block = clip(max_floats // (B·width), 2, 64)``.
    """

    def __init__(self, num_envs: int, width: int, normal: bool = False, max_floats: int = 4_000_000) -> None:
        self.width = width
        self.normal = normal
        self.block = int(np.clip(max_floats // max(1, num_envs * width), 2, 64))
        self.generators = [np.random.default_rng() for _ in range(num_envs)]
        self.buffer = np.empty((num_envs, self.block, width))
        self.pos = np.full(num_envs, self.block)  # every block starts empty

    def seed(self, b: int, generator: np.random.Generator) -> None:
        """Give formation ``b`` a new generator (its unread numbers are dropped)."""
        self.generators[b] = generator
        self.pos[b] = self.block

    def refill(self, ids: np.ndarray | None = None, rows: int = 1) -> None:
        """Make sure every formation of ``ids`` (all if None) has ``rows`` unread rows.

        A formation with fewer keeps its unread rows, moved to the front of its
        block, and draws the rest of the block after them, so its sequence is
        unchanged. Afterwards its next rows are ``buffer[b, pos[b]:]`` (the
        compiled channel reads them there and advances ``pos`` itself).
        """
        if not 1 <= rows <= self.block:
            raise ValueError(f"rows must be in [1, {self.block}] (the block size), got {rows}")
        left = self.block - self.pos
        short = np.flatnonzero(left < rows) if ids is None else np.asarray(ids)[left[ids] < rows]
        for b in short:
            keep = left[b]
            if keep:
                self.buffer[b, :keep] = self.buffer[b, self.pos[b] :].copy()
            gen, fresh = self.generators[b], self.buffer[b, keep:]
            if self.normal:
                gen.standard_normal(out=fresh)
            else:
                gen.random(out=fresh)
        self.pos[short] = 0

    def take(self, ids: np.ndarray) -> np.ndarray:
        """The next row of each formation in ``ids``: ``(len(ids), width)``."""
        self.refill(ids)
        rows = self.buffer[ids, self.pos[ids]]
        self.pos[ids] += 1
        return rows
