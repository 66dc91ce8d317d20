"""A go-to-goal controller for a differential-drive chair."""

from gotogoal.controller import GoToGoal

__all__ = ["GoToGoal"]
