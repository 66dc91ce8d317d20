"""A ROS 2 node on DDS: what makes a cyclonedds participant a node of a ROS 2 graph.

``RosNode(name)`` joins ``ROS_DOMAIN_ID`` (``config.domain_id``) with the Cyclone
configuration of ``config.xml`` and follows ROS 2 Jazzy's conventions, those of
``rmw_cyclonedds_cpp`` and ``rmw_fastrtps_cpp`` alike:

- the topic ``/odom`` is the DDS topic ``rt/odom``; the type ``nav_msgs/msg/Odometry``
  is ``nav_msgs::msg::dds_::Odometry_`` (``types``), plain CDR, final;
- each endpoint has its ROS QoS and ``typehash=RIHS01_...;`` in USER_DATA (``qos``);
  the participant's USER_DATA is ``enclave=/;``;
- the participant publishes a ``rmw_dds_common/msg/ParticipantEntitiesInfo`` on
  ``ros_discovery_info`` (transient local) naming the node and the GIDs (DDS GUIDs)
  of its readers and writers, which is what ``ros2 node list`` and ``ros2 node info``
  read; it is written again whenever an endpoint is added.

A DDS stack that cannot start raises ``WcdriveConnectionError`` naming Cyclone DDS and
what to check; a missing ``cyclonedds`` package names the package to install; on the
network without unicast peers, multicast that does not work here raises before the
participant starts (``multicast.check``).
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from wcdrive.errors import WcdriveConnectionError, WcdriveError
from wcdrive.ros2.dds import config

if TYPE_CHECKING:
    from wcdrive.ros2.dds.qos import Profile

DISCOVERY_TOPIC = "ros_discovery_info"
ENTITIES_INFO = "rmw_dds_common/msg/ParticipantEntitiesInfo"


def _dds() -> Any:
    """The cyclonedds modules, or a clear error saying how to get them."""
    try:
        import cyclonedds.core
        import cyclonedds.domain
        import cyclonedds.pub
        import cyclonedds.sub
        import cyclonedds.topic
    except ImportError as exc:
        raise WcdriveError(
            "wcdrive ros2 needs Cyclone DDS's Python binding, which did not load "
            f"({exc}): pip install cyclonedds (it bundles the C library)") from exc
    return cyclonedds


def topic_name(name: str) -> str:
    """ROS topic ``/odom`` (or ``odom``, in the root namespace) -> DDS topic ``rt/odom``."""
    return "rt/" + name.lstrip("/")


class Publisher:
    """A ROS 2 publisher: ``publish(message)`` takes a dict in the message's layout or
    an instance of ``types.idl_class(msgtype)``."""

    def __init__(self, writer: Any, msgtype: str) -> None:
        self.writer, self.msgtype = writer, msgtype

    def publish(self, message: Any) -> None:
        """Writes ``message`` (an instance of the topic's IDL class, or a dict of its
        fields) on the topic."""
        from wcdrive.ros2.dds import types

        sample = message if isinstance(message, types.idl_class(self.msgtype)) else types.build(
            self.msgtype, message)
        self.writer.write(sample)


class RosNode:
    """One ROS 2 node (``name`` in ``namespace``) on its own DDS participant (module
    docstring). ``network``, ``peers``, ``interface``: ``config.xml``'s. Close it."""

    def __init__(self, name: str, namespace: str = "/", *, domain: int | None = None,
                 network: bool = False, peers: tuple[str, ...] = (), interface: str | None = None) -> None:
        dds = _dds()
        from cyclonedds.core import DDSException, Policy, Qos

        self.name, self.namespace = name, namespace
        self.domain_id = config.domain_id() if domain is None else domain
        self.network = network
        self._lock = threading.Lock()
        self._readers: list[Any] = []
        self._writers: list[Any] = []
        self._topics: dict[str, Any] = {}
        self._closed = False
        if network and not peers:
            from wcdrive.ros2.dds import multicast

            multicast.check(interface if interface and interface[:1].isdigit() else None)
        try:
            self._domain = dds.domain.Domain(self.domain_id, config.xml(network, peers, interface))
            self.participant = dds.domain.DomainParticipant(
                self.domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        except DDSException as exc:
            where = "the network" if network else "the loopback interface (127.0.0.1)"
            raise WcdriveConnectionError(
                f"Cyclone DDS could not join ROS 2 domain {self.domain_id} on {where}: {exc}. "
                "Check that the interface exists and is up"
                + (", that multicast is allowed on it or --peer names the other hosts" if network else "")
                + ", and that no firewall blocks UDP ports 7400 and above") from exc
        from wcdrive.ros2.dds.qos import DISCOVERY

        self._info = self._writer(DISCOVERY_TOPIC, ENTITIES_INFO, DISCOVERY, announce=False)
        self.announce()

    @property
    def guid(self) -> bytes:
        """The participant's GUID, 16 bytes: its GID in the ROS graph."""
        return bytes(self.participant.get_guid().bytes)

    def _topic(self, dds_name: str, msgtype: str) -> Any:
        from cyclonedds.topic import Topic

        from wcdrive.ros2.dds import types

        topic = self._topics.get(dds_name)
        if topic is None:
            topic = self._topics[dds_name] = Topic(self.participant, dds_name, types.idl_class(msgtype))
        return topic

    def _writer(self, dds_name: str, msgtype: str, profile: Profile, announce: bool = True) -> Any:
        from cyclonedds.pub import DataWriter

        from wcdrive.ros2.dds import qos, types

        writer = DataWriter(self.participant, self._topic(dds_name, msgtype),
                            qos=qos.qos(profile, types.type_hash(msgtype)))
        if announce:
            with self._lock:
                self._writers.append(writer)
            self.announce()
        return writer

    def publisher(self, topic: str, msgtype: str, profile: Profile) -> Publisher:
        """A publisher of ``msgtype`` (``pkg/msg/Msg``) on ROS topic ``topic``."""
        return Publisher(self._writer(topic_name(topic), msgtype, profile), msgtype)

    def subscription(self, topic: str, msgtype: str, profile: Profile) -> Any:
        """A DDS reader of ROS topic ``topic`` (``take()`` the samples)."""
        from cyclonedds.sub import DataReader

        from wcdrive.ros2.dds import qos, types

        reader = DataReader(self.participant, self._topic(topic_name(topic), msgtype),
                            qos=qos.qos(profile, types.type_hash(msgtype)))
        with self._lock:
            self._readers.append(reader)
        self.announce()
        return reader

    def entities_info(self) -> dict[str, Any]:
        """The ``ParticipantEntitiesInfo`` this node publishes, as a dict."""
        def gid(entity: Any) -> dict[str, list[int]]:
            return {"data": list(bytes(entity.get_guid().bytes))}

        with self._lock:
            readers, writers = list(self._readers), list(self._writers)
        return {"gid": {"data": list(self.guid)},
                "node_entities_info_seq": [{
                    "node_namespace": self.namespace, "node_name": self.name,
                    "reader_gid_seq": [gid(r) for r in readers],
                    "writer_gid_seq": [gid(w) for w in writers]}]}

    def announce(self) -> None:
        """Writes the node's ``ros_discovery_info`` again."""
        from wcdrive.ros2.dds import types

        self._info.write(types.build(ENTITIES_INFO, self.entities_info()))

    def close(self) -> None:
        """Leaves the graph (the participant and all it made). Safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        # An empty node list first, so that graph caches drop the node at once.
        try:
            from wcdrive.ros2.dds import types

            self._info.write(types.build(ENTITIES_INFO, {"gid": {"data": list(self.guid)}}))
        except Exception:
            pass
        _delete(self.participant)       # with its readers, writers and topics
        _delete(self._domain)


def _delete(entity: Any) -> None:
    """Deletes a cyclonedds entity now rather than when Python collects it."""
    entity.__del__()
