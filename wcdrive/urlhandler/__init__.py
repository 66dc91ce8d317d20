"""pyserial URL handlers of wcdrive: ``wcsim://`` (see ``protocol_wcsim``).

Importing ``wcdrive`` registers this package with pyserial, so
``serial.serial_for_url("wcsim://")`` works in any program that imported wcdrive;
``python -m wcdrive.miniterm wcsim://`` is miniterm with it registered.
"""
