"""The one definition of the observation layouts: the vehicle agents' features
(:data:`VEHICLE_OBS_FEATURES`, docs/model.md §2.4) and the RRA layout (docs/model.md §4.6).

Every RRA agent (one per V2V link: the follower's predecessor → the follower, i−1 → i in one
platoon; docs/model.md §6) observes, per subframe, the features of :data:`RRA_OBS_FEATURES` in
this order. The twin fills them (:meth:`~vdtn_marl.sim.twin.DigitalTwin.rra_observation`), the
environments take their observation spaces from :meth:`RRAFeatureLayout.bounds`, and the RRA
baselines read their inputs through :class:`RRAFeatureLayout`; none of them writes an index by
hand.

===========================  =====  ==========================================================
feature                      width  content
===========================  =====  ==========================================================
``own_snr``                  M      own V2V link SNR at maximum power, per sub-channel, 10 dB
``bs_interference``          M      INR it would cause at the BS at maximum power, 10 dB
``v2i_interference``         M      INR it receives from each sub-channel's V2I user, 10 dB
``occupancy``                M      V2V links that transmitted on it last subframe / L
``cam_bits_left``            1      fraction of the CAM's bits still to send (> 0: the CAM is
                                    pending and the action has an effect; 0: the link is
                                    silent)
``time_left``                1      fraction of the interval left
``gap_error``                1      recipient's e_p / 15 m at the interval start
``speed_error``              1      recipient's e_v / 10 m/s
``pred_accel``               1      predecessor's acceleration / u_max
``command``                  1      recipient's command in force, u_{k−1} / u_max
``cam_age``                  1      age of the CAM content the recipient holds at kΔt, in
                                    control intervals (1: last interval's CAM arrived),
                                    clipped to :data:`RRA_CAM_AGE_CLIP_INTERVALS`
``cam_delay_history``        H      delivery subframes of the recipient's last H CAMs,
                                    d/(T+1), newest first; 1 = lost
``command_history``          C      recipient's earlier commands u_{k−2}, u_{k−3}, … / u_max
===========================  =====  ==========================================================

With ``RadioParams.rra_cam_innovation`` one block follows them (:data:`RRA_CAM_INNOVATION`):

===========================  =====  ==========================================================
``cam_innovation``           2      the predecessor's acceleration and command at kΔt minus
                                    the ones in the CAM the recipient holds, / u_max
===========================  =====  ==========================================================

The last three blocks are what predicts the recipient's IVoI (how stale its information is,
whether its last CAMs arrived, how it has been acting): the seed paper asks the RRA state to
hold what predicts the IVoI, and its companion (Lei et al., Part II) augments the RRA state
with the control action history.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Vehicle observation features, in order (docs/model.md §2.4): what every vehicle agent
#: observes of itself, its predecessor and the CAM it holds (filled by
#: :func:`vdtn_marl.sim.platoon.vehicle_observation`).
VEHICLE_OBS_FEATURES = (
    "gap_error_m",
    "speed_error_mps",
    "accel_mps2",
    "cam_pred_accel_mps2",
    "cam_pred_command_mps2",
    "cam_delay_ms",
    "cam_age_ms",
    "prev_command_mps2",
)

#: RRA CSI features are dB ratios in units of this many dB, clipped to ``RRA_OBS_GAIN_CLIP``.
RRA_OBS_GAIN_SCALE_DB = 10.0
RRA_OBS_GAIN_CLIP = (-5.0, 15.0)  # in units of 10 dB
#: Clip of the normalised control features (errors and commands).
RRA_CONTROL_CLIP = 5.0
RRA_CAM_AGE_CLIP_INTERVALS = 10.0
#: CAM delays (H) and earlier commands (C) of the recipient in the RRA observation.
RRA_DELAY_HISTORY = 3
RRA_COMMAND_HISTORY = 2


@dataclass(frozen=True)
class Feature:
    """One block of the RRA observation: ``width`` values (× M when ``per_subchannel``),
    each within [``low``, ``high``]."""

    name: str
    low: float
    high: float
    width: int = 1
    per_subchannel: bool = False


_GAIN = RRA_OBS_GAIN_CLIP
_CTRL = (-RRA_CONTROL_CLIP, RRA_CONTROL_CLIP)

RRA_OBS_FEATURES: tuple[Feature, ...] = (
    Feature("own_snr", *_GAIN, per_subchannel=True),
    Feature("bs_interference", *_GAIN, per_subchannel=True),
    Feature("v2i_interference", *_GAIN, per_subchannel=True),
    Feature("occupancy", 0.0, 1.0, per_subchannel=True),
    Feature("cam_bits_left", 0.0, 1.0),
    Feature("time_left", 0.0, 1.0),
    Feature("gap_error", *_CTRL),
    Feature("speed_error", *_CTRL),
    Feature("pred_accel", *_CTRL),
    Feature("command", *_CTRL),
    Feature("cam_age", 0.0, RRA_CAM_AGE_CLIP_INTERVALS),
    Feature("cam_delay_history", 0.0, 1.0, width=RRA_DELAY_HISTORY),
    Feature("command_history", *_CTRL, width=RRA_COMMAND_HISTORY),
)
"""The RRA observation features, in order (see the module doc)."""

#: The block appended with ``RadioParams.rra_cam_innovation``: what delivering this interval's
#: CAM would change in what the recipient holds (docs/model.md §4.6).
RRA_CAM_INNOVATION = Feature("cam_innovation", *_CTRL, width=2)

#: The control block (recipient's errors, predecessor's acceleration, recipient's command).
RRA_CONTROL_BLOCK = ("gap_error", "speed_error", "pred_accel", "command")
#: The features that predict the recipient's IVoI.
RRA_IVOI_BLOCK = ("cam_age", "cam_delay_history", "command_history")


@dataclass(frozen=True)
class RRAFeatureLayout:
    """Where each feature of :data:`RRA_OBS_FEATURES` sits for M sub-channels.

    ``layout[name]`` is the slice of a feature; the attributes name the blocks the RRA
    baselines read (``bits_left`` and ``time_left`` are single indices).
    """

    num_subchannels: int
    slices: dict[str, slice]
    dim: int
    features: tuple[Feature, ...] = RRA_OBS_FEATURES

    @classmethod
    def from_radio(cls, radio) -> RRAFeatureLayout:
        return cls.for_subchannels(radio.num_subchannels, radio.rra_cam_innovation)

    @classmethod
    def for_subchannels(
        cls, num_subchannels: int, cam_innovation: bool = False
    ) -> RRAFeatureLayout:
        features = RRA_OBS_FEATURES + ((RRA_CAM_INNOVATION,) if cam_innovation else ())
        slices, start = {}, 0
        for feature in features:
            width = feature.width * (num_subchannels if feature.per_subchannel else 1)
            slices[feature.name] = slice(start, start + width)
            start += width
        return cls(num_subchannels=num_subchannels, slices=slices, dim=start, features=features)

    def __getitem__(self, name: str) -> slice:
        try:
            return self.slices[name]
        except KeyError:
            raise KeyError(f"RRA feature {name!r} is not one of {', '.join(self.slices)}") from None

    def block(self, names: tuple[str, ...]) -> slice:
        """The slice spanning consecutive features ``names``."""
        return slice(self[names[0]].start, self[names[-1]].stop)

    @property
    def own_snr(self) -> slice:
        return self["own_snr"]

    @property
    def bs_interference(self) -> slice:
        return self["bs_interference"]

    @property
    def v2i_interference(self) -> slice:
        return self["v2i_interference"]

    @property
    def csi(self) -> slice:
        return self.block(("own_snr", "bs_interference", "v2i_interference"))

    @property
    def occupancy(self) -> slice:
        return self["occupancy"]

    @property
    def bits_left(self) -> int:
        return self["cam_bits_left"].start

    @property
    def time_left(self) -> int:
        return self["time_left"].start

    @property
    def control(self) -> slice:
        return self.block(RRA_CONTROL_BLOCK)

    @property
    def ivoi(self) -> slice:
        return self.block(RRA_IVOI_BLOCK)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bound of every feature, float32 [dim] each."""
        low = np.empty(self.dim, np.float32)
        high = np.empty(self.dim, np.float32)
        for feature in self.features:
            low[self[feature.name]] = feature.low
            high[self[feature.name]] = feature.high
        return low, high

    def names(self) -> list[str]:
        """One name per observation column (``own_snr[2]``, ``cam_delay_history[0]``, …)."""
        out = []
        for feature in self.features:
            width = self[feature.name].stop - self[feature.name].start
            out += [feature.name] if width == 1 else [f"{feature.name}[{j}]" for j in range(width)]
        return out
