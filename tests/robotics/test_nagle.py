"""``disable_nagle``: the option set on the listener reaches every socket it accepts (what the
Foxglove endpoint relies on, the SDK exposing neither), IPv4 and IPv6; nothing found, nothing done."""

from __future__ import annotations

import socket

import pytest

from wott_hub.robotics.nagle import ESTABLISHED, descriptors, disable_nagle


def _nodelay(sock: socket.socket) -> int:
    return sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)


@pytest.mark.parametrize("family, host", [(socket.AF_INET, "127.0.0.1"), (socket.AF_INET6, "::1")])
def test_a_listener_s_accepted_sockets_get_tcp_nodelay(family, host):
    with socket.socket(family) as listener:
        listener.bind((host, 0))
        listener.listen()
        port = listener.getsockname()[1]
        assert _nodelay(listener) == 0
        assert disable_nagle(port) == 1
        assert _nodelay(listener) == 1
        with socket.create_connection((host, port)) as client:
            accepted, _ = listener.accept()
            with accepted:
                assert _nodelay(accepted) == 1
                assert descriptors(port, ESTABLISHED) == [accepted.fileno()]
            assert _nodelay(client) == 0  # the client side is the client's business


def test_no_listener_no_change():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))  # bound, not listening
        port = s.getsockname()[1]
        assert disable_nagle(port) == 0
        assert _nodelay(s) == 0
