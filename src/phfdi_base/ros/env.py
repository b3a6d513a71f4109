"""The environment every ROS process of phfdi runs in (no rclpy import here).

DDS must stay on this machine: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
(discovery by unicast to 127.0.0.1, data over shared memory). Every entry point
calls :func:`ensure_localhost` before rclpy starts, so nobody can forget it.
Each launched graph (and each test) gets a ROS domain of its own from
:func:`reserve_domain_id`.
"""

from __future__ import annotations

import errno
import fcntl
import os
import random
import socket
import tempfile
from dataclasses import dataclass
from pathlib import Path

from phfdi_base.errors import UserError

DISCOVERY_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
#: ROS domain ids usable on Linux (the DDS port formula overflows above 232)
DOMAIN_IDS = range(1, 233)
#: restricts the ids :func:`reserve_domain_id` picks from, e.g. ``60-79`` (machines shared by several teams)
DOMAINS_VAR = "PHFDI_ROS_DOMAINS"


def allowed_domain_ids(environ: dict | None = None) -> list[int]:
    """The domain ids this process may pick: ``PHFDI_ROS_DOMAINS=LO-HI`` (inclusive) if set, else 1..232.

    Examples
    --------
    >>> allowed_domain_ids({"PHFDI_ROS_DOMAINS": "60-62"})
    [60, 61, 62]
    """
    value = (os.environ if environ is None else environ).get(DOMAINS_VAR, "").strip()
    if not value:
        return list(DOMAIN_IDS)
    try:
        lo, _, hi = value.partition("-")
        ids = list(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        raise UserError(f"{DOMAINS_VAR}={value}: expected LO-HI, e.g. 60-79") from None
    if not ids or ids[0] not in DOMAIN_IDS or ids[-1] not in DOMAIN_IDS:
        raise UserError(f"{DOMAINS_VAR}={value}: expected LO-HI within 1..232, e.g. 60-79")
    return ids


def ensure_localhost(environ: dict | None = None) -> None:
    """Set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST if unset; refuse any other value."""
    env = os.environ if environ is None else environ
    value = env.get(DISCOVERY_VAR, "")
    if value == "":
        env[DISCOVERY_VAR] = "LOCALHOST"
    elif value.upper() != "LOCALHOST":
        raise UserError(f"{DISCOVERY_VAR}={value}: phfdi keeps DDS traffic on this machine; "
                        f"unset it or set {DISCOVERY_VAR}=LOCALHOST")


#: set by the launcher to its PID: a node started by it ends when it ends (:func:`die_with_launcher`)
LAUNCHER_PID_VAR = "PHFDI_LAUNCHER_PID"


def die_with_launcher(environ: dict | None = None) -> bool:
    """In a node the launcher started (``PHFDI_LAUNCHER_PID`` set): ask for SIGTERM when the launcher dies
    (``PR_SET_PDEATHSIG``). False if the launcher is gone already (the node should not start)."""
    value = (os.environ if environ is None else environ).get(LAUNCHER_PID_VAR, "")
    if not value.isdigit():
        return True
    import ctypes
    import signal

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG
    return os.getppid() == int(value)  # else the launcher died before the request: no signal will come


#: Fast DDS participant profile of graph processes: faster discovery of nodes that start apart (see the file)
DISCOVERY_PROFILE = Path(__file__).with_name("fastdds_discovery.xml")
#: the variables Fast DDS reads its default XML profile from (2.x; 3.x); a user's own profile is left alone
PROFILE_VARS = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def use_discovery_profile(environ: dict | None = None) -> None:
    """Point Fast DDS at :data:`DISCOVERY_PROFILE` unless a profile file is set already."""
    env = os.environ if environ is None else environ
    if not any(env.get(v) for v in PROFILE_VARS):
        env[PROFILE_VARS[0]] = str(DISCOVERY_PROFILE)


def graph_env(domain_id: int, base: dict | None = None) -> dict[str, str]:
    """Environment for a process of a graph on ``domain_id``."""
    env = dict(os.environ if base is None else base)
    use_discovery_profile(env)
    env[DISCOVERY_VAR] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _domain_ports(domain_id: int) -> list[int]:
    # RTPS well-known ports: PB 7400 + DG 250 * domain; unicast metatraffic
    # and user ports of the first participants (+10 + 2 i, +11 + 2 i).
    base = 7400 + 250 * domain_id
    return [base + 10 + i for i in range(6)]


def _ports_free(ports: list[int]) -> bool:
    for port in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("0.0.0.0", port))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    return False
                raise
    return True


@dataclass
class DomainLease:
    """A ROS domain id held for this process (a lock file) until :meth:`release`."""

    domain_id: int
    _fd: int | None

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "DomainLease":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _lock_dir() -> Path:
    d = Path(tempfile.gettempdir()) / "phfdi-ros-domains"
    d.mkdir(exist_ok=True)
    return d


def exported_domain_id(environ: dict | None = None) -> int | None:
    """The ROS_DOMAIN_ID the user exported (None when unset or empty); one line when it is not a domain id.

    Examples
    --------
    >>> exported_domain_id({"ROS_DOMAIN_ID": "42"}), exported_domain_id({})
    (42, None)
    """
    value = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not value:
        return None
    try:
        domain_id = int(value)
    except ValueError:
        raise UserError(f"ROS_DOMAIN_ID={value} (exported): not a number; use 0..232 or unset it") from None
    if domain_id != 0 and domain_id not in DOMAIN_IDS:
        raise UserError(f"ROS_DOMAIN_ID={value} (exported): use 0..232 or unset it")
    return domain_id


def reserve_domain_id(requested: int | None = None, environ: dict | None = None) -> DomainLease:
    """A domain id no other phfdi graph holds and no DDS participant on this machine uses.

    Held by a lock file (released when this process ends), so parallel
    launches and test workers never share a domain. ``requested`` (``--domain-id``) checks and holds that id
    instead of picking one; else an exported ``ROS_DOMAIN_ID`` is the request (a ROS user's own nodes are on
    it: silently replacing it put the graph where they could not see it); otherwise the id is one of
    :func:`allowed_domain_ids`.
    """
    source = "--domain-id"
    if requested is None:
        requested = exported_domain_id(environ)
        source = "ROS_DOMAIN_ID (exported)"
    if requested is None:
        allowed = allowed_domain_ids()
        candidates = random.sample(allowed, len(allowed))
    else:
        candidates = [requested]
    if requested is not None and requested not in DOMAIN_IDS and requested != 0:
        raise UserError(f"--domain-id {requested}: use 0..232")
    for d in candidates:
        fd = os.open(_lock_dir() / f"{d}.lock", os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            if requested is not None:
                raise UserError(f"ROS domain {d} ({source}) is in use by another phfdi graph; pick another "
                                "--domain-id" + (" or unset ROS_DOMAIN_ID" if source != "--domain-id" else "")
                                ) from None
            continue
        if requested is not None or _ports_free(_domain_ports(d)):
            return DomainLease(d, fd)
        os.close(fd)
    ids = allowed_domain_ids()
    raise UserError(f"no free ROS domain id ({ids[0]}..{ids[-1]}) on this machine")


if __name__ == "__main__":  # prints a free domain id (for scripts/launch_graph.sh)
    with reserve_domain_id() as lease:
        print(lease.domain_id)
