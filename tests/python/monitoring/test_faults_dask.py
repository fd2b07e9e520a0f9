"""Issue 26, item 5: the Dask cluster modaluq starts (``workers=N``) accepts only mutual-TLS
connections made with its throw-away certificate and serves no HTTP (docs/monitoring.md §2, security)."""

import os
import signal
import socket
import ssl
import subprocess
import sys
import time

import pytest
from monitoring_support import SETTINGS, assert_same_tracks

from modaluq.monitoring import monitor, simulate_monitoring
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


def test_every_comm_of_a_started_cluster_is_tls(started):
    addresses = _comm_addresses(started)
    assert len(addresses) == 5 and all(a.startswith("tls://") for a in addresses), addresses
    assert started.submit(sum, [1, 2]).result() == 3  # the client that has the certificate works


@pytest.mark.parametrize("how", ["plain tcp", "tls without a certificate", "tls with another certificate"])
def test_a_client_without_the_cluster_key_cannot_connect(started, how):
    host, port = _host_port(started.scheduler.address)
    address = f"{'tcp' if how == 'plain tcp' else 'tls'}://{host}:{port}"
    security = "distributed.security.Security.temporary()" if how == "tls with another certificate" else "None"
    # no code of this client may run on the workers: it never gets a connection. In a process of its
    # own, killed after a minute: a client refused by TLS may retry or hang instead of failing fast,
    # and must not hang the suite (a process that ran the code prints RAN before anything else)
    code = (
        "import sys, distributed\n"
        f"security = {security}\n"
        "try:\n"
        f"    with distributed.Client({address!r}, security=security, timeout='3s', set_as_default=False) as c:\n"
        "        print('RAN', c.submit(sum, [1, 2]).result(timeout=3), flush=True)\n"
        "except Exception as exc:\n"
        "    print('REFUSED', type(exc).__name__, flush=True)\n"
    )
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
    assert "RAN" not in out, out


def _answer_to_http(port):
    """The first bytes a server on ``port`` answers to an HTTP GET (b"" if it closes or says nothing)."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.settimeout(5)
        s.sendall(b"GET / HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
        try:
            return s.recv(64)
        except (TimeoutError, ConnectionResetError):
            return b""


def _tls_certificate_name(port):
    """The common name of the certificate a TLS server on ``port`` presents (TLS 1.3 completes the
    handshake before the server checks the client's certificate, which this client lacks)."""
    context = ssl.create_default_context()
    context.check_hostname, context.verify_mode = False, ssl.CERT_NONE
    with socket.create_connection(("127.0.0.1", port), timeout=5) as raw, \
            context.wrap_socket(raw, server_hostname="127.0.0.1") as tls:
        der = tls.getpeercert(binary_form=True)
    from cryptography import x509

    return x509.load_der_x509_certificate(der).subject.rfc4514_string()


def test_the_http_servers_dask_opens_are_closed_and_no_comm_port_speaks_http(started):
    http_ports = [started.run_on_scheduler(lambda dask_scheduler: dask_scheduler.http_server.port),
                  *started.run(lambda dask_worker: dask_worker.http_server.port).values()]
    assert len(http_ports) == 3
    for port in http_ports:
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection(("127.0.0.1", port), timeout=5).close()
    for address in _comm_addresses(started):
        port = _host_port(address)[1]
        assert not _answer_to_http(port).startswith(b"HTTP/"), address
        assert _tls_certificate_name(port) == "CN=dask-internal", address


def _listening_ports(driver) -> set:
    """The TCP ports the driver and its descendants listen on. A short-lived child (a spawn
    helper) can exit between the listing and the look at its sockets: it is skipped, and the
    listing is taken again until two agree."""
    def once():
        ports = set()
        for p in [driver, *driver.children(recursive=True)]:
            try:
                ports |= {(c.laddr.ip, c.laddr.port) for c in p.net_connections("tcp") if c.status == psutil.CONN_LISTEN}
            except psutil.NoSuchProcess:
                if p.pid == driver.pid:
                    raise
        return ports

    previous, deadline = once(), time.time() + 10
    while time.time() < deadline:
        time.sleep(0.2)
        current = once()
        if current == previous:
            return current
        previous = current
    return previous


@pytest.mark.slow
def test_while_modaluq_monitor_workers_2_runs_only_its_tls_comm_ports_listen(tmp_path):
    """What `ss -ltnp` shows during `modaluq monitor --workers 2`: the listeners of the driver (scheduler,
    nannies) and of its worker processes are 5 TLS ports on 127.0.0.1, none answering HTTP."""
    folder = tmp_path / "site"
    # enough records that the run outlasts the probes (it is killed after them): with 20, a fast
    # run once ended between the listing and the probe of its last port (connection refused)
    simulate_monitoring(120, n_samples=20000, seed=2).write(folder, format="npz")
    cmd = [sys.executable, "-m", "modaluq.cli", "monitor", str(folder), "--out", str(tmp_path / "tracks.nc"),
           "--orders", "2:40:2", "--workers", "2", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.time() + 180
        while time.time() < deadline and len(list((tmp_path / "tracks.parts").glob("*.json"))) < 2:
            time.sleep(0.05)  # settings.json + a record: the cluster is up and running records
        driver = psutil.Process(proc.pid)
        listening = _listening_ports(driver)
        assert proc.poll() is None, "the run ended before its listeners could be seen"
        assert len(listening) == 5 and {ip for ip, _ in listening} == {"127.0.0.1"}, listening
        for _, port in sorted(listening):
            assert not _answer_to_http(port).startswith(b"HTTP/"), port
            assert _tls_certificate_name(port) == "CN=dask-internal", port
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the driver and its workers
        proc.wait()


def test_without_cryptography_a_cluster_is_refused_not_started_in_plain_tcp(monkeypatch):
    monkeypatch.setitem(sys.modules, "cryptography", None)  # import cryptography -> ImportError
    with pytest.raises(ImportError, match="cryptography"), executor_for(None, None, 2, None):
        pytest.fail("a cluster was started without TLS")


@pytest.mark.slow
def test_a_run_on_a_started_cluster_gives_the_thread_pool_results(serial, campaign):
    assert_same_tracks(serial, monitor(campaign.records, settings=SETTINGS, workers=2, progress=False),
                       other_process=True)
