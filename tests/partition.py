"""A test host of our own whose network can be cut: a Linux network namespace joined to this one by a
veth pair, and a TCP forwarder on this side of the pair (Redis and PostgreSQL listen on loopback only,
or on another test host's address).

Several hosts make a star: this namespace is the network between them. Each host reaches this side of
its own pair (its :attr:`TestHost.gateway`), where its forwarder relays each port to a service here or on
another host (:meth:`TestHost.forward`); this namespace reaches every host's :attr:`TestHost.address`
directly. The processes of a host also have a machine name of their own (a UTS namespace:
``socket.gethostname()`` is :attr:`TestHost.hostname`), as on separate machines.

Cutting the link makes its packets vanish both ways (each side's neighbour entry for the other is
pointed at a MAC address nobody has): the link stays up and no error comes back, as when a machine
stops answering. Restoring it forgets those entries, so ARP finds the real peer again and the
connections that waited resume (a request left waiting by a cut of 25 or 40 s was answered within a
second of the restore, here).

Needs root and ``ip`` (iproute2). Run the forwarder alone with::

    python -m tests.partition LISTEN_HOST:PORT=TARGET_HOST:PORT ...
"""

from __future__ import annotations

import asyncio
import ipaddress
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: A MAC address no interface has (locally administered): frames sent to it are dropped by the peer.
NOWHERE = "02:00:5e:00:00:01"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=30)


def unavailable() -> str | None:
    """Why a namespace cannot be made here (None if it can): not root, no ``ip``, or ``ip netns`` refused."""
    if os.geteuid() != 0:
        return "needs root to make a network namespace (ip netns)"
    if shutil.which("ip") is None:
        return "needs iproute2's ip for network namespaces"
    probe = f"nh-probe-{secrets.token_hex(3)}"
    made = _ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"ip netns is unavailable here: {made.stderr.strip()}"
    _ip("netns", "del", probe, check=False)
    return None


#: Third octets of the subnets handed out in this process (their hosts may not be created yet).
_TAKEN: set[int] = set()


def _free_subnet() -> ipaddress.IPv4Network:
    """A /30 in 10.213.0.0/16 that no interface or route here uses, nor another host of this process."""
    used = _ip("-4", "addr").stdout + _ip("-4", "route").stdout
    while True:
        octet = secrets.randbelow(256)
        if octet not in _TAKEN and f"10.213.{octet}." not in used:
            _TAKEN.add(octet)
            return ipaddress.IPv4Network(f"10.213.{octet}.{4 * secrets.randbelow(64)}/30")


class TestHost:
    """A network namespace reachable at :attr:`address` (its side of the veth) from :attr:`gateway`
    (ours), with forwarders on the gateway to services that listen on loopback here (or on another
    host's address). ``name`` goes into :attr:`hostname`, the machine name of its processes."""

    __test__ = False  # not a pytest class

    def __init__(self, name: str = "host") -> None:
        tag = secrets.token_hex(3)
        self.name, self.hostname = name, f"nh-{name}-{tag}"
        self.namespace, self.here, self.there = f"nonholonomic-{tag}", f"nh{tag}h", f"nh{tag}n"
        net = _free_subnet()
        self.gateway, self.address = (str(a) for a in list(net.hosts())[:2])
        self._forwarder: subprocess.Popen | None = None
        self._processes: list[subprocess.Popen] = []

    def create(self) -> TestHost:
        """Make the namespace and the veth pair, both sides up with their addresses."""
        _ip("netns", "add", self.namespace)
        _ip("link", "add", self.here, "type", "veth", "peer", "name", self.there)
        _ip("link", "set", self.there, "netns", self.namespace)
        _ip("addr", "add", f"{self.gateway}/30", "dev", self.here)
        _ip("link", "set", self.here, "up")
        for args in (("addr", "add", f"{self.address}/30", "dev", self.there), ("link", "set", self.there, "up"),
                     ("link", "set", "lo", "up")):
            _ip("netns", "exec", self.namespace, "ip", *args)
        return self

    def forward(self, targets: Sequence[tuple[str, int] | tuple[str, int, int]], log: Path) -> None:
        """Forward ``gateway:port`` to ``host:port`` for each target ``(host, port)``, or ``gateway:listen``
        to ``host:port`` for ``(host, port, listen)``; returns when listening."""
        routes = [f"{self.gateway}:{target[2] if len(target) == 3 else target[1]}={target[0]}:{target[1]}"
                  for target in targets]
        self._forwarder = subprocess.Popen([sys.executable, "-m", "tests.partition", *routes], cwd=ROOT,
                                           stdout=log.open("w"), stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 30
        while "listening" not in log.read_text():
            if self._forwarder.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the forwarder did not start: {log.read_text()}")
            time.sleep(0.05)

    def popen(self, cmd: Sequence[str], **kwargs) -> subprocess.Popen:
        """Start ``cmd`` inside the namespace, on a machine named :attr:`hostname` (``ip netns exec``,
        ``unshare`` and ``sh`` each exec the next: the pid is the command's)."""
        proc = subprocess.Popen(["ip", "netns", "exec", self.namespace, "unshare", "--uts", "--", "sh", "-c",
                                 'hostname "$0" && exec "$@"', self.hostname, *cmd], **kwargs)
        self._processes.append(proc)
        return proc

    def cut(self) -> None:
        """Packets between the two sides vanish from now on."""
        _ip("netns", "exec", self.namespace, "ip", "neigh", "replace", self.gateway, "lladdr", NOWHERE,
            "dev", self.there, "nud", "permanent")
        _ip("neigh", "replace", self.address, "lladdr", NOWHERE, "dev", self.here, "nud", "permanent")

    def restore(self) -> None:
        """The link works again (ARP resolves the real peers)."""
        _ip("netns", "exec", self.namespace, "ip", "neigh", "del", self.gateway, "dev", self.there, check=False)
        _ip("neigh", "del", self.address, "dev", self.here, check=False)

    def destroy(self) -> None:
        """Kill every process left in the namespace and the forwarder, delete the namespace and the veth."""
        for proc in self._processes:
            if proc.poll() is None:
                proc.kill()
        listed = _ip("netns", "pids", self.namespace, check=False).stdout.split()
        for pid in listed:  # pool processes of a worker started here, and anything they started
            try:
                os.kill(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass
        for proc in self._processes:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                pass
        if self._forwarder is not None and self._forwarder.poll() is None:
            self._forwarder.kill()
            self._forwarder.wait(10)
        _ip("netns", "del", self.namespace, check=False)
        _ip("link", "del", self.here, check=False)  # gone with the namespace's side, unless that failed


# -- the forwarder -----------------------------------------------------------------------------------


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    try:
        while data := await reader.read(65536):
            writer.write(data)
            await writer.drain()
    except (ConnectionError, OSError):
        pass
    finally:
        writer.close()


async def _serve(routes: list[str]) -> None:
    servers = []
    for route in routes:
        listen, target = route.split("=")
        (host, port), (to_host, to_port) = listen.rsplit(":", 1), target.rsplit(":", 1)

        async def connect(reader, writer, to_host=to_host, to_port=int(to_port)) -> None:
            try:
                up_reader, up_writer = await asyncio.open_connection(to_host, to_port)
            except OSError:
                writer.close()
                return
            await asyncio.gather(_pipe(reader, up_writer), _pipe(up_reader, writer))

        servers.append(await asyncio.start_server(connect, host, int(port)))
    print("listening", flush=True)
    await asyncio.gather(*(s.serve_forever() for s in servers))


if __name__ == "__main__":
    asyncio.run(_serve(sys.argv[1:]))
