"""The Cyclone DDS configuration of the bridge, and the ROS 2 domain.

``domain_id()``: ``ROS_DOMAIN_ID`` (0 when unset), checked against the range whose
ports the DDS port mapping can hold (0 to 232).

``xml(network=False)``: this host only (the default), as ROS 2 Jazzy does with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``: the loopback interface alone, no
multicast, discovery by unicast to 127.0.0.1 (Cyclone probes the ports of the first
``MAX_PARTICIPANTS`` participant indices there). A process elsewhere on the network
neither sees the bridge nor can reach it: the bridge has no locator but 127.0.0.1.
``xml(network=True)``: Cyclone's own choice of network interface, multicast discovery
(the SPDP group 239.255.0.1), plus unicast ``peers`` for a network that blocks
multicast. Anyone in the domain on that network can then publish ``/cmd_vel``.

In both, for the sake of Fast DDS (ROS 2 Jazzy's default middleware):

- ``Internal/GenerateKeyhash``: every keyed sample, and so the disposals and
  unregistrations of the discovery topics the bridge sends when it leaves (SIGTERM,
  Ctrl-C, ``RosNode.close``), carries the key hash inline. Cyclone sends a disposal
  without it by default (a key payload only), which Fast DDS 2.14 ignores: the bridge's
  endpoints then stayed in a Fast DDS node's graph until their lease ran out (10 s).
- ``Discovery/SPDPInterval`` (``SPDP_INTERVAL``) and
  ``Discovery/InitialLocatorPruneDelay`` (``inf``): the bridge announces itself to
  every configured peer address (here the discovery ports of the first
  ``MAX_PARTICIPANTS`` participants on 127.0.0.1) every ``SPDP_INTERVAL``, for as long
  as it runs. By default Cyclone 11 pings an address where nobody answers once at
  start, again only after 30 s, and drops it after 30 s: a Fast DDS node started later
  on Jazzy's default discovery range (SUBNET: multicast, which the bridge does not
  join by default) was never found.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from xml.sax.saxutils import quoteattr

from wcdrive.errors import WcdriveError

#: The highest domain id the default DDS port mapping allows (7400 + 250 * id + ...).
MAX_DOMAIN_ID = 232
#: How many participants on this host the loopback discovery probes for.
MAX_PARTICIPANTS = 32
#: How often the bridge announces itself (SPDP) to each peer address, answered or not.
SPDP_INTERVAL = "1s"


def domain_id(environ: dict[str, str] | None = None) -> int:
    """``ROS_DOMAIN_ID`` of ``environ`` (default ``os.environ``), 0 when unset."""
    text = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError:
        raise WcdriveError(f"ROS_DOMAIN_ID={text!r} is not a number (0 to {MAX_DOMAIN_ID})") from None
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise WcdriveError(f"ROS_DOMAIN_ID={value} is out of range (0 to {MAX_DOMAIN_ID})")
    return value


def xml(network: bool = False, peers: Sequence[str] = (), interface: str | None = None) -> str:
    """The Cyclone DDS configuration (module docstring). ``interface``: with
    ``network``, the interface name or address to use instead of Cyclone's choice."""
    if not network:
        if peers or interface:
            raise WcdriveError("--peer and --interface need --network (the default is this host only)")
        general = ('<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
                   "<AllowMulticast>false</AllowMulticast>")
        discovery = ("<ParticipantIndex>auto</ParticipantIndex>"
                     f"<MaxAutoParticipantIndex>{MAX_PARTICIPANTS}</MaxAutoParticipantIndex>"
                     '<Peers><Peer address="127.0.0.1"/></Peers>')
    else:
        general = ""
        if interface:
            key = "address" if interface[:1].isdigit() else "name"
            general = f"<Interfaces><NetworkInterface {key}={quoteattr(interface)}/></Interfaces>"
        discovery = "<ParticipantIndex>auto</ParticipantIndex>"
        discovery += f"<MaxAutoParticipantIndex>{MAX_PARTICIPANTS}</MaxAutoParticipantIndex>"
        if peers:
            discovery += "<Peers>" + "".join(f"<Peer address={quoteattr(p)}/>" for p in peers) + "</Peers>"
    discovery += (f"<SPDPInterval>{SPDP_INTERVAL}</SPDPInterval>"
                  "<InitialLocatorPruneDelay>inf</InitialLocatorPruneDelay>")
    return (f'<CycloneDDS><Domain id="any"><General>{general}</General>'
            f"<Discovery>{discovery}</Discovery>"
            "<Internal><GenerateKeyhash>true</GenerateKeyhash></Internal></Domain></CycloneDDS>")
