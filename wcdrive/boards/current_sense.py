"""The motors' current senses as the simulated boards wire them: a bidirectional Hall
sensor in each motor lead (Allegro ACS758LCB-050B: 40 mV/A, VCC/2 at 0 A, ratiometric to
the 5 V that is also the ADC's reference) on analog inputs A1 (left, ``CURRENT_CHANNELS``)
and A2 (right).

``current_millivolts(amps)`` is what a motor current of ``amps`` puts on its input
(``ZERO_MV`` at 0 A, ``MV_PER_AMP`` a amp, clipped to the 0 to 5 V a 5 V sensor can
give), and ``plant_current_millivolts(plant)`` what the plant's motors put there as the
plant last computed them (``Plant.left.current``, ``Plant.right.current``). Every board
starts at ``ZERO_MV`` on both: a motor at rest. The ADC makes counts of them as it does
of the supply (``wcdrive.boards.supply_sense.adc_counts``); the firmware reads 0 A at
its CURRENT_ZERO_COUNTS, CURRENT_AMPS_PER_COUNT amps a count (5 V / 1024 / 40 mV).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from wcdrive.boards.supply_sense import AVCC_MV
from wcdrive.firmware import constants as C

if TYPE_CHECKING:
    from wcdrive.plant import Plant

__all__ = ["CURRENT_CHANNELS", "MV_PER_AMP", "ZERO_MV", "current_millivolts", "plant_current_millivolts"]

#: The analog input of each motor's current sense: A1 left, A2 right.
CURRENT_CHANNELS = {"left": C.PIN_CURRENT_L, "right": C.PIN_CURRENT_R}
#: The sensor's output at 0 A (VCC/2), mV.
ZERO_MV = AVCC_MV // 2
#: The sensor's sensitivity, mV per A (ACS758LCB-050B at 5 V).
MV_PER_AMP = 40


def current_millivolts(amps: float) -> int:
    """The millivolts a motor current of ``amps`` (either way) puts on its input:
    ``ZERO_MV + MV_PER_AMP * amps``, rounded to the mV, within 0 to ``AVCC_MV``."""
    return min(AVCC_MV, max(0, round(ZERO_MV + MV_PER_AMP * float(amps))))


def plant_current_millivolts(plant: Plant) -> dict[str, int]:
    """The millivolts the plant's motors put on A1 and A2 now, by side: their currents
    as the plant's last step computed them."""
    return {"left": current_millivolts(plant.left.current), "right": current_millivolts(plant.right.current)}
