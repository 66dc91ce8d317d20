"""``wcdrive sim``: scenarios (``scenario``), the closed loop of host, firmware and
plant (``runner``), and what a run prints and draws (``report``)."""
