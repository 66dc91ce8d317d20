"""``wcdrive sim``: scenarios (``scenario``), the closed loop of host, firmware and
plant (``runner``, with the run's host in ``host``), what a run gives (``result``), and
what it prints and draws (``report``)."""
