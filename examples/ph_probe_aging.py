"""A user block: an ageing pH glass electrode whose slope falls with time.

Plugged into a scenario with::

    extends: paper
    plugins: [ph_probe_aging.py]          # relative to the scenario file
    sensors:
      ph:
        extra: [{type: probe_aging, params: {slope_loss_per_hour: 0.01}}]

The block protocol (phfdi_base.blocks): ``reset(x0)``, ``step(x, t_s) -> y``, an
optional ``severity`` in [0, 1], and ``register_block(name)`` so scenario
files can name it.
"""

from dataclasses import dataclass

from phfdi_base.blocks import register_block


@register_block("probe_aging")
@dataclass
class ProbeAging:
    """Electrode slope (Nernst response) falling linearly from 100 % at t = 0: y = 7 + s(t) (x - 7)."""

    slope_loss_per_hour: float = 0.01  # fraction of slope lost per hour
    severity: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.slope_loss_per_hour < 1.0:
            raise ValueError(f"slope_loss_per_hour must be in [0, 1), got {self.slope_loss_per_hour}")

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        slope = max(0.0, 1.0 - self.severity * self.slope_loss_per_hour * t_s / 3600.0)
        return 7.0 + slope * (x - 7.0)
