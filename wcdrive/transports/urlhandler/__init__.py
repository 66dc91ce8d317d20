"""pyserial URL handlers of wcdrive: ``wcsim://`` (the simulated chair: the port and the
plant), ``wcavr://`` (the compiled firmware in simavr driving the plant) and
``wccan://`` (a chair on a CAN bus). A robot plugin brings its own, outside this
package: ``wceddie://`` (a simulated Eddie) is ``wcdrive.eddie.serial_url``.

``serial.serial_for_url("wcsim://")`` works in any program: the
``wcdrive-serial-urls.pth`` hook installed with wcdrive answers pyserial's import of
``serial.urlhandler.protocol_<scheme>`` with these modules (and the plugins', every
scheme of the ``wcdrive.serial_urls`` entry-point group), so
``python -m serial.tools.miniterm wcsim://`` needs no import of wcdrive. Importing
``wcdrive`` also registers this package with pyserial.
"""
