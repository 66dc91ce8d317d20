"""The pymunk model of the chair: ``Plant`` (body, motors, wheels, casters),
``ChairParams`` and the sensors."""

from wcdrive.plant.chair import Plant, WheelView
from wcdrive.plant.params import ChairParams
from wcdrive.plant.sensors import Gyro, encoder_counts

__all__ = ["ChairParams", "Gyro", "Plant", "WheelView", "encoder_counts"]
