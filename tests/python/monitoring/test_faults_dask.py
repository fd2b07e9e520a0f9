"""Issue 26, item 5: the Dask cluster modaluq starts (``workers=N``) accepts only mutual-TLS
connections made with its throw-away certificate and serves no HTTP (docs/monitoring.md §2, security)."""

import socket
import sys

import pytest
from monitoring_support import SETTINGS, assert_same_tracks

from modaluq.monitoring import monitor
from modaluq.monitoring.executors import executor_for

distributed = pytest.importorskip("distributed")
pytest.importorskip("cryptography")
psutil = pytest.importorskip("psutil")
pytest.importorskip("xarray")


@pytest.fixture(scope="module")
def started():
    """The client of a cluster of 2 workers started by the package's own code path (monitor's ``workers=2``)."""
    with executor_for(None, None, 2, None) as (_, remote):
        assert remote
        yield distributed.default_client()


def _host_port(address):
    host, port = address.split("://", 1)[1].rsplit(":", 1)
    return host, int(port)


def _comm_addresses(client):
    """The comm addresses of the scheduler, the workers and their nannies."""
    workers = client.scheduler_info()["workers"]
    return [client.scheduler.address, *workers, *(w["nanny"] for w in workers.values())]


def _listening_ports():
    """The TCP ports that this process (scheduler, nannies) and its children (the workers) listen on."""
    processes = [psutil.Process(), *psutil.Process().children(recursive=True)]
    return {c.laddr.port for p in processes for c in p.net_connections("tcp") if c.status == psutil.CONN_LISTEN}


def test_every_comm_of_a_started_cluster_is_tls(started):
    addresses = _comm_addresses(started)
    assert len(addresses) == 5 and all(a.startswith("tls://") for a in addresses), addresses
    assert started.submit(sum, [1, 2]).result() == 3  # the client that has the certificate works


@pytest.mark.parametrize("how", ["plain tcp", "tls without a certificate", "tls with another certificate"])
def test_a_client_without_the_cluster_key_cannot_connect(started, how):
    host, port = _host_port(started.scheduler.address)
    if how == "plain tcp":
        address, security = f"tcp://{host}:{port}", None
    else:
        address = f"tls://{host}:{port}"
        security = None if how == "tls without a certificate" else distributed.security.Security.temporary()
    with pytest.raises((OSError, TypeError, ValueError)):
        # no code of this client may run on the workers: it never gets a connection
        with distributed.Client(address, security=security, timeout="3s", set_as_default=False) as intruder:
            intruder.submit(sum, [1, 2]).result(timeout=3)


def test_only_the_tls_comm_ports_listen_and_none_speaks_http(started):
    comm_ports = {_host_port(a)[1] for a in _comm_addresses(started)}
    listening = _listening_ports()
    assert listening == comm_ports, f"listening {sorted(listening)}, comm ports {sorted(comm_ports)}"
    for port in sorted(listening):
        with socket.create_connection(("127.0.0.1", port), timeout=3) as s:
            s.settimeout(3)
            s.sendall(b"GET / HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
            try:
                answer = s.recv(64)
            except (TimeoutError, ConnectionResetError):
                answer = b""
        assert not answer.startswith(b"HTTP/"), (port, answer)


def test_without_cryptography_a_cluster_is_refused_not_started_in_plain_tcp(monkeypatch):
    monkeypatch.setitem(sys.modules, "cryptography", None)  # import cryptography -> ImportError
    with pytest.raises(ImportError, match="cryptography"), executor_for(None, None, 2, None):
        pytest.fail("a cluster was started without TLS")


@pytest.mark.slow
def test_a_run_on_a_started_cluster_gives_the_thread_pool_results(serial, campaign):
    assert_same_tracks(serial, monitor(campaign.records, settings=SETTINGS, workers=2, progress=False),
                       other_process=True)
