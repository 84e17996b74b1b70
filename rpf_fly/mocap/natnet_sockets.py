"""The NatNet client's UDP sockets (rpf_fly/mocap/natnet_client.py): the command socket that sends every command
and receives the replies and unicast frames, and the data socket that receives multicast frames (or unicast ones
sent to the data port).

Both are non-blocking with a 4 MiB receive buffer, which holds the frames between two reads of the client. The
data socket binds with SO_REUSEADDR, so several clients on one host can listen to one multicast group.
"""

from __future__ import annotations

import socket
import sys

RECEIVE_BUFFER = 4 << 20
"""Bytes of the sockets' kernel receive buffer (SO_RCVBUF)."""


def resolve_ipv4(host: str) -> str:
    """The IPv4 address of ``host`` (NatNet is IPv4 only)."""
    return str(socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)[0][4][0])  # AF_INET: (host, port)


def open_command_socket(local_ip: str) -> socket.socket:
    """The command socket, bound to ``local_ip`` on an ephemeral port."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
        sock.bind((local_ip, 0))
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock


def open_data_socket(port: int, *, multicast: bool, group: str, membership_ip: str, local_ip: str) -> socket.socket:
    """The data socket on ``port``: joined to ``group`` on the interface ``membership_ip`` (multicast), or bound
    to ``local_ip`` (unicast)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
        if multicast:
            # Linux filters by destination when bound to the group; Windows can only bind INADDR_ANY.
            sock.bind((group if sys.platform.startswith("linux") else "", port))
            membership = socket.inet_aton(group) + socket.inet_aton(membership_ip)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        else:
            sock.bind((local_ip, port))
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock
