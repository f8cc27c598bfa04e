"""A scenario's topology and geometry as index arrays (docs/model.md §6).

The physics reads who leads, who follows whom, which V2V link carries which CAM, which vehicle
uses which V2I sub-channel and where everyone drives from a :class:`Topology`, never from a
hard-coded chain. Scenarios (:mod:`vdtn_marl.scenarios`) build one; without one the twin runs
:func:`platoon_topology`, one platoon with predecessor following (PF): vehicle 0 leads and
vehicle i follows vehicle i−1.

Conventions, for N vehicles of which Λ lead and F = N − Λ follow:

============================  ====================================================================
``predecessor[i]``            the vehicle that i follows (its gap and speed error are to it, and it
                              receives its CAMs), or ``-1``: i leads and drives a speed trace
``leaders``                   vehicles with predecessor −1, in increasing index (trace j drives
                              ``leaders[j]``)
``followers``                 the others, in increasing index; follower row f of every ``[B, F]``
                              array (commands, rewards, vehicle observations) is vehicle
                              ``followers[f]``
``link_tx``, ``link_rx``      one V2V link per follower: link l carries the CAM of
                              ``predecessor[followers[l]]`` to ``followers[l]``, so link rows
                              and follower rows coincide (link l's RRA agent is paid follower
                              l's IVoI)
``v2i_order``                 sub-channel m is the V2I uplink of vehicle ``v2i_order[m mod N]``
``lateral_offset_m[i]``       centre of vehicle i's lane across the road (m, towards the base
                              stations, which stand at ``bs_road_offset_m``); all 0: one lane
``leader_position_m[j]``      where leader j starts along the road (m); each follower starts at
                              its desired gap behind its predecessor
============================  ====================================================================

A :class:`Topology` holds only tuples (it is hashable and travels in checkpoints as numbers).
The physics takes rows with :meth:`Topology.followers_of`, :meth:`Topology.predecessors_of` and
:meth:`Topology.leaders_of`, and puts leader and follower rows back together with
:meth:`Topology.assemble`: gathers with index arrays (slices where the rows are contiguous, as
in PF), on torch tensors or NumPy arrays, never a loop over vehicles. The module imports torch
only when it is given a tensor, so the parameters and the scenarios (and the config schema that
reads them) are read without it.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from functools import cache, cached_property, lru_cache
from typing import TYPE_CHECKING

import numpy as np

from vdtn_marl.errors import ConfigError

if TYPE_CHECKING:
    import torch

    from vdtn_marl.sim.backend import Array

LEADER = -1
"""``predecessor`` of a vehicle that leads (follows a speed trace)."""


@dataclass(frozen=True)
class Topology:
    """Who leads, who follows whom, and where they drive (see the module doc).

    ``lateral_offset_m`` [N], ``leader_position_m`` [Λ] and ``v2i_order`` [N] default to one
    lane, every leader at 0 m and ``0..N−1``. Invalid input raises :class:`ConfigError` naming
    the key, the value and what is allowed.
    """

    predecessor: tuple[int, ...]
    lateral_offset_m: tuple[float, ...] | None = None
    leader_position_m: tuple[float, ...] | None = None
    v2i_order: tuple[int, ...] | None = None
    name: str = "platoon"

    def __post_init__(self) -> None:
        _validate(self)

    # ------------------------------------------------------------------ who is who
    @property
    def num_vehicles(self) -> int:
        return len(self.predecessor)

    @property
    def leaders(self) -> tuple[int, ...]:
        return self._rows.leaders

    @property
    def followers(self) -> tuple[int, ...]:
        return self._rows.followers

    @property
    def num_leaders(self) -> int:
        return len(self.leaders)

    @property
    def num_followers(self) -> int:
        return len(self.followers)

    @property
    def num_links(self) -> int:
        """One V2V link per follower."""
        return len(self.followers)

    @property
    def link_tx(self) -> tuple[int, ...]:
        """Transmitter of each V2V link [L]: the predecessor of its recipient."""
        return tuple(self.predecessor[i] for i in self.followers)

    @property
    def link_rx(self) -> tuple[int, ...]:
        """Recipient of each V2V link [L]: follower l."""
        return self.followers

    @property
    def leader_of(self) -> tuple[int, ...]:
        """For each vehicle [N], the row j of the leader at the head of its chain."""
        return self._rows.leader_of

    @property
    def follows_leader(self) -> tuple[bool, ...]:
        """For each follower [F], whether its predecessor is a leader (whose CAM carries a
        trace's acceleration rather than a follower's command)."""
        leaders = set(self.leaders)
        return tuple(p in leaders for p in self.link_tx)

    @property
    def single_lane(self) -> bool:
        return self.lateral_offset_m is None or not any(self.lateral_offset_m)

    def v2i_user(self, num_subchannels: int) -> tuple[int, ...]:
        """The vehicle whose V2I uplink uses each sub-channel [M]."""
        order = self.v2i_order or tuple(range(self.num_vehicles))
        return tuple(order[m % len(order)] for m in range(num_subchannels))

    # ------------------------------------------------------------------ rows of arrays
    @cached_property
    def _rows(self) -> _Rows:
        """:func:`_rows` of this topology, kept on the instance: the lookups below run in the
        simulator's inner loops, where hashing the topology for a cache costs more than the
        indexing."""
        return _rows(self)

    def row_indices(self) -> _Rows:
        """The index objects of the methods below (slices where rows are contiguous, else
        int64 arrays), for code that indexes NumPy arrays in a tight loop."""
        return self._rows

    def followers_of(self, x: Array) -> Array:
        """``x[:, followers]``: [B, N, ...] → [B, F, ...]."""
        i = self._rows.follower_index
        return x[:, i if type(i) is slice or type(x) is np.ndarray else _index(i, x)]

    def predecessors_of(self, x: Array) -> Array:
        """Each follower's predecessor's row: [B, N, ...] → [B, F, ...]."""
        i = self._rows.predecessor_index
        return x[:, i if type(i) is slice or type(x) is np.ndarray else _index(i, x)]

    def leaders_of(self, x: Array) -> Array:
        """``x[:, leaders]``: [B, N, ...] → [B, Λ, ...]."""
        i = self._rows.leader_index
        return x[:, i if type(i) is slice or type(x) is np.ndarray else _index(i, x)]

    def assemble(self, leader_rows: Array, follower_rows: Array) -> Array:
        """[B, N] from leader rows [B, Λ] and follower rows [B, F] (the inverse of
        :meth:`leaders_of` and :meth:`followers_of`)."""
        if isinstance(leader_rows, np.ndarray):
            joined = np.concatenate([leader_rows, follower_rows], axis=1)
        else:
            joined = _torch().cat([leader_rows, follower_rows], dim=1)
        order = self._rows.assemble_index
        return joined if order is None else joined[:, _index(order, joined)]

    def chain_matrix(self) -> np.ndarray:
        """[F, F] float64: entry (f, g) is 1 when follower g is f itself or one of the
        followers between f and its leader (the spacings that add up to f's distance behind
        its leader)."""
        return self._rows.chain


@dataclass(frozen=True)
class _Rows:
    """Index objects derived once per topology: slices where rows are contiguous, else int64
    arrays."""

    leaders: tuple[int, ...]
    followers: tuple[int, ...]
    leader_of: tuple[int, ...]
    leader_index: slice | np.ndarray
    follower_index: slice | np.ndarray
    predecessor_index: slice | np.ndarray
    assemble_index: np.ndarray | None  # None: [leaders, followers] is already 0..N−1
    chain: np.ndarray


def _as_index(rows: tuple[int, ...]) -> slice | np.ndarray:
    """A slice when ``rows`` are consecutive increasing integers, else an int64 array."""
    if rows and all(b == a + 1 for a, b in zip(rows, rows[1:], strict=False)):
        return slice(rows[0], rows[-1] + 1)
    return np.asarray(rows, np.int64)


@lru_cache(maxsize=64)
def _rows(topology: Topology) -> _Rows:
    pred = topology.predecessor
    leaders = tuple(i for i, p in enumerate(pred) if p == LEADER)
    followers = tuple(i for i, p in enumerate(pred) if p != LEADER)
    head = {}
    for i in range(len(pred)):
        j = i
        while pred[j] != LEADER:
            j = pred[j]
        head[i] = leaders.index(j)
    joined = leaders + followers
    inverse = np.argsort(np.asarray(joined, np.int64))
    row = {v: f for f, v in enumerate(followers)}
    chain = np.zeros((len(followers), len(followers)))
    for f, v in enumerate(followers):
        while pred[v] != LEADER:
            chain[f, row[v]] = 1.0
            v = pred[v]
    return _Rows(
        leaders=leaders,
        followers=followers,
        leader_of=tuple(head[i] for i in range(len(pred))),
        leader_index=_as_index(leaders),
        follower_index=_as_index(followers),
        predecessor_index=_as_index(tuple(pred[i] for i in followers)),
        assemble_index=None if joined == tuple(range(len(pred))) else inverse,
        chain=chain,
    )


@cache
def _torch():
    """torch, imported when the first tensor comes (see the module doc)."""
    import torch

    return torch


@lru_cache(maxsize=256)
def _torch_index(rows: tuple[int, ...], device: torch.device) -> torch.Tensor:
    torch = _torch()
    return torch.tensor(rows, dtype=torch.long, device=device)


def _index(index: slice | np.ndarray, x: Array):
    """``index`` as ``x`` can be indexed with it (a torch tensor on ``x``'s device for torch)."""
    if isinstance(index, slice) or isinstance(x, np.ndarray):
        return index
    return _torch_index(tuple(index.tolist()), x.device)


@lru_cache(maxsize=64)
def platoon_topology(num_vehicles: int) -> Topology:
    """One platoon with predecessor following: vehicle 0 leads, vehicle i follows i−1, one
    lane, the leader at 0 m, sub-channel m the uplink of vehicle m mod N (docs/model.md §4.1)."""
    return Topology(predecessor=(LEADER, *range(num_vehicles - 1)))


def _validate(t: Topology) -> None:
    pred, n = t.predecessor, len(t.predecessor)
    if not isinstance(pred, tuple) or not all(
        isinstance(p, numbers.Integral) and not isinstance(p, bool) for p in pred
    ):
        raise ConfigError(f"topology.predecessor={pred!r} must be a tuple of vehicle indices")
    if not 2 <= n <= 64:
        raise ConfigError(f"topology.predecessor has {n} vehicles; allowed: 2 to 64")
    for i, p in enumerate(pred):
        if p != LEADER and not 0 <= p < n:
            raise ConfigError(
                f"topology.predecessor[{i}]={p} points outside the platoon; allowed: "
                f"{LEADER} (vehicle {i} leads) or another vehicle in 0..{n - 1}"
            )
    if LEADER not in pred:
        raise ConfigError(
            f"topology.predecessor={pred!r} has no leader; allowed: at least one entry "
            f"{LEADER} (a vehicle that drives a speed trace)"
        )
    for i in range(n):
        seen, j = [i], pred[i]
        while j != LEADER:
            if j in seen:
                loop = " → ".join(str(v) for v in seen[seen.index(j) :] + [j])
                raise ConfigError(
                    f"topology.predecessor={pred!r} has a cycle {loop}; allowed: chains of "
                    f"predecessors that each end at a leader ({LEADER})"
                )
            seen.append(j)
            j = pred[j]
    leaders = pred.count(LEADER)
    if t.lateral_offset_m is not None:
        _check_numbers("topology.lateral_offset_m", t.lateral_offset_m, n, 100.0)
    if t.leader_position_m is not None:
        _check_numbers("topology.leader_position_m", t.leader_position_m, leaders, 1e5)
    if t.v2i_order is not None and sorted(t.v2i_order) != list(range(n)):
        raise ConfigError(
            f"topology.v2i_order={t.v2i_order!r} must order every vehicle 0..{n - 1} once"
        )


def _check_numbers(key: str, values, count: int, bound: float) -> None:
    ok = isinstance(values, tuple) and len(values) == count
    ok = ok and all(
        isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= bound for v in values
    )
    if not ok:
        raise ConfigError(
            f"{key}={values!r} must hold {count} numbers (m) within [-{bound:g}, {bound:g}]"
        )
