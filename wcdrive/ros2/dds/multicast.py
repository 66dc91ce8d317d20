"""Whether DDS discovery by multicast can work here: ``check()``.

DDS finds its peers by multicast (SPDP, group 239.255.0.1, port 7400 + 250 * domain
id) unless unicast peers are given. Where multicast is blocked (no multicast route,
an interface without MULTICAST, a firewall that drops the group), a participant
starts happily and then sees nobody. So before ``--network`` joins without
``--peer``, ``check`` sends one datagram to the group from this host, with multicast
loop on, and waits for it to come back; when it does not, it raises
``WcdriveConnectionError`` naming multicast and what to do instead. It cannot see a
switch or router elsewhere that drops multicast: it proves the local half only.
"""

from __future__ import annotations

import os
import select
import socket
import struct

from wcdrive.errors import WcdriveConnectionError

GROUP = "239.255.0.1"


def check(interface_address: str | None = None, timeout: float = 1.0) -> None:
    """Raises ``WcdriveConnectionError`` when a datagram sent to ``GROUP`` (from
    ``interface_address``, default the system's choice) does not come back."""
    token = os.urandom(8)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    try:
        receiver.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        receiver.bind(("", 0))
        port = receiver.getsockname()[1]
        local = socket.inet_aton(interface_address or "0.0.0.0")
        receiver.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                            struct.pack("4s4s", socket.inet_aton(GROUP), local))
        sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        if interface_address:
            sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, local)
        sender.sendto(token, (GROUP, port))
        while True:
            ready, _, _ = select.select([receiver], [], [], timeout)
            if not ready:
                raise OSError(f"nothing came back in {timeout} s")
            if receiver.recv(64) == token:
                return
    except OSError as exc:
        raise WcdriveConnectionError(
            f"multicast does not work here ({GROUP}: {exc}), so DDS discovery on the network "
            "would find nobody: name the other hosts with --peer HOST (unicast discovery), or "
            "allow multicast on the interface (ip link set <if> multicast on; the firewall: "
            "UDP to 239.255.0.1, ports 7400 and above)") from exc
    finally:
        receiver.close()
        sender.close()
