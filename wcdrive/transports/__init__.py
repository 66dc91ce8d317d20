"""Ways to reach a board: the ``Port`` interface, the pty bridge, the CAN link and the
recording port. The pyserial URL handlers are in ``wcdrive.transports.urlhandler``."""
