"""The chair on a CAN bus (python-can): the frame mapping (``codec``), the host side
link behind ``can://`` (``link.CanLink``) and the gateway that puts a chair's serial
port on a bus (``gateway.CanGateway``). protocol/CAN.md and protocol/wcdrive.dbc
document the frames."""
