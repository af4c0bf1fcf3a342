"""Shared fixtures: the loopback-only network namespace and the two-node Ray cluster."""

from __future__ import annotations

import ctypes
import os
import socket
import subprocess

import pytest

CLONE_NEWNET = 0x40000000


def enter_loopback_namespace() -> None:
    """Move this process into a new network namespace with loopback up (needs root).

    Every Ray address is then 127.0.0.1 and nothing listens on the machine's network; the rest
    of the pytest session stays in the namespace (no other test needs a network).
    """
    if [name for _, name in socket.if_nameindex()] == ["lo"]:
        return  # already in one (e.g. run under `unshare -n`)
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(CLONE_NEWNET) != 0:
        pytest.skip(
            f"a network namespace needs root (unshare: {os.strerror(ctypes.get_errno())}); "
            "run the Ray tests as root, or under `unshare -rn`"
        )
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    assert [name for _, name in socket.if_nameindex()] == ["lo"]


@pytest.fixture(scope="session")
def ray_cluster():
    """A real two-node Ray cluster (one CPU each) on 127.0.0.1, shared by the Ray tests."""
    from ray import cluster_utils  # here: Ray takes a second to import; the ray extra is a test need

    enter_loopback_namespace()
    cluster = cluster_utils.Cluster(
        initialize_head=True, head_node_args={"num_cpus": 1, "node_ip_address": "127.0.0.1"}
    )
    cluster.add_node(num_cpus=1, node_ip_address="127.0.0.1")
    cluster.wait_for_nodes()
    try:
        yield cluster
    finally:
        cluster.shutdown()
