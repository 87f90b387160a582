"""``--cluster``: a real Dask scheduler and two workers on loopback (``dask scheduler``, ``dask worker``),
started here and stopped after.  The same answers as one process, to the byte; a worker killed
mid-request loses no request and changes no answer; a cluster left without workers names the
models it could not search; a scheduler that cannot be reached is one line; ``build --cluster``
writes the same database; and without ``--cluster`` nothing of Dask is imported."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

import tactrec  # noqa: E402
from tactrec.bench.answers import without_timings  # noqa: E402
from tactrec.bench.common import random_site_touch  # noqa: E402
from tactrec.cli import main  # noqa: E402
from tactrec.database import load_database  # noqa: E402
from tactrec.errors import InputError  # noqa: E402
from tactrec.io.session import SessionTouch, save_session  # noqa: E402
from tactrec.io.touch import load_touch, save_touch  # noqa: E402
from tactrec.recognition import Recognizer  # noqa: E402
from tactrec.simulation import random_rigid_motion, sensor_to_world  # noqa: E402

#: where the package under test lies, for the workers' imports
SOURCE = str(Path(tactrec.__file__).resolve().parents[1])
#: 12 mm curves 60 degrees apart, a little noise: the small meshes' touches
TOUCH = dict(points=41, spacing=0.3, angle=60.0, noise=0.01, noise_kind="gaussian", outward=False)
CLOSED_FORM = ["sphere-33", "cylinder-50"]


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([SOURCE] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _tactrec(*args, stdin=None, timeout=120.0, **options) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tactrec", *map(str, args)], input=stdin, capture_output=True,
                          text=True, env=_env(), timeout=timeout, **options)


def _dask(*args, log: Path) -> subprocess.Popen:
    with open(log, "w") as handle:
        return subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=handle, stderr=subprocess.STDOUT,
                                env=_env(), start_new_session=True)


@contextlib.contextmanager
def _cluster(folder: Path, workers: int = 2):
    """A scheduler and ``workers`` workers on loopback: ``(address, {worker address: process})``;
    every process is stopped after."""
    from distributed import Client

    folder.mkdir(parents=True, exist_ok=True)
    file = folder / "scheduler.json"
    processes = [_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                       str(file), log=folder / "scheduler.log")]
    try:
        deadline = time.monotonic() + 30.0
        while not (file.exists() and file.stat().st_size) and time.monotonic() < deadline:
            time.sleep(0.05)
        address = json.loads(file.read_text())["address"]
        for k in range(workers):
            processes.append(_dask("worker", address, "--nthreads", "1", "--no-nanny", "--host", "127.0.0.1",
                                   "--no-dashboard", log=folder / f"worker{k}.log"))
        with Client(address, timeout=10, set_as_default=False) as client:
            client.wait_for_workers(workers, timeout=30)
            pids = client.run(os.getpid)
        by_pid = {p.pid: p for p in processes}
        yield address, {a: by_pid[pid] for a, pid in sorted(pids.items())}
    finally:
        for p in processes:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def database(small, tmp_path_factory):
    """The four small meshes (PLY files) and two closed-form surfaces, built into a database here:
    ``(folder, model sources)``."""
    import trimesh

    folder = tmp_path_factory.mktemp("cluster")
    sources = []
    for entry in small:
        path = folder / f"{entry.name}.ply"
        trimesh.Trimesh(entry.model.vertices, entry.model.faces, process=False).export(path)
        sources.append(str(path))
    sources += CLOSED_FORM
    assert main(["build", *sources, "--out", str(folder / "db"), "--units", "mm", "--quiet"]) == 0
    return folder / "db", sources


@pytest.fixture(scope="module")
def touches(small, tmp_path_factory):
    """A seeded touch of each small mesh, written as a touch file."""
    folder = tmp_path_factory.mktemp("touches")
    paths = []
    for k, entry in enumerate(small):
        path = folder / f"{entry.name}-0.json"
        save_touch(random_site_touch(entry.model, np.random.default_rng((68, k)), TOUCH), path)
        paths.append(path)
    return paths


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with _cluster(tmp_path_factory.mktemp("dask")) as (address, workers):
        yield address, workers


def _answers(lines: str) -> list:
    return [without_timings(json.loads(line)) for line in lines.strip().splitlines()]


def test_touches_and_a_session_answer_the_same_json_on_the_cluster_as_in_one_process(database, touches, cluster,
                                                                                  small, tmp_path, capsys):
    db, _ = database
    entry = small[1]
    pose = random_rigid_motion(np.random.default_rng(68), extent=50.0)
    steps = [random_site_touch(entry.model, np.random.default_rng((69, i)), TOUCH) for i in range(2)]
    session = tmp_path / "session.json"
    save_session([SessionTouch(t, *sensor_to_world(t, pose)) for t in steps], session)
    runs = {}
    for where in ((), ("--cluster", cluster[0])):
        assert main(["recognize", *map(str, touches), str(session), "--db", str(db), "--json", *where]) == 0
        answers = _answers(capsys.readouterr().out)
        assert main(["next", str(session), "--db", str(db), "--json", *where]) == 0
        runs[where] = answers + _answers(capsys.readouterr().out)
    one, spread = runs.values()
    assert spread == one
    assert [a["best"] for a in one[:len(touches)]] == [p.name.rsplit("-", 1)[0] for p in touches]


def test_in_python_the_client_keeps_no_distance_field_and_workers_must_see_the_folder(database, touches, cluster):
    """A :class:`Recognizer` on the cluster: the one process's answer, while this process holds the models
    without their distance fields (the workers search on them); a database folder the workers cannot
    see is an :class:`InputError` naming it."""
    from tactrec.cluster import connect

    db, _ = database
    touch = load_touch(touches[0])
    with Recognizer(load_database(db)) as recognizer:
        one = without_timings(recognizer.recognize(touch).to_json())
    light = load_database(db, fields=False)
    with connect(cluster[0]) as spread:
        with Recognizer(light, cluster=spread) as recognizer:
            assert without_timings(recognizer.recognize(touch).to_json()) == one
        elsewhere = [dataclasses.replace(e, stored=(f"{db}-elsewhere", e.stored[1])) for e in light.entries]
        with pytest.raises(InputError, match=f"{db}-elsewhere: not readable on the Dask worker"):
            Recognizer(elsewhere, cluster=spread)
    meshes = [e.model for e in light.entries if e.model.kind == "mesh"]
    assert meshes and not any("distance_field" in m.__dict__ or "outer_field" in m.__dict__ for m in meshes)


def test_a_scheduler_that_cannot_be_reached_is_one_line_and_status_2(database, touches, capsys):
    db, _ = database
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        refused = f"tcp://127.0.0.1:{free.getsockname()[1]}"
    with socket.socket() as silent, socket.socket() as babbling:
        silent.bind(("127.0.0.1", 0))                 # listens, never speaks: not a Dask scheduler
        silent.listen(1)
        quiet = f"127.0.0.1:{silent.getsockname()[1]}"
        babbling.bind(("127.0.0.1", 0))               # greets as another kind of server does
        babbling.listen(1)
        threading.Thread(target=lambda: babbling.accept()[0].sendall(b"SSH-2.0-OpenSSH_9.2\r\n"), daemon=True).start()
        other = f"tcp://127.0.0.1:{babbling.getsockname()[1]}"
        for address in (refused, quiet, "local:none"):
            start = time.monotonic()
            assert main(["recognize", str(touches[0]), "--db", str(db), "--cluster", address]) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and err.startswith(f"tactrec: {address}: "), err
            assert time.monotonic() - start < 30.0
        out = _tactrec("recognize", touches[0], "--db", db, "--cluster", other)      # its whole life, to the exit
        assert out.returncode == 2 and out.stderr.count("\n") == 1 and out.stderr.startswith(f"tactrec: {other}: "), \
            out.stderr


def test_build_on_the_cluster_writes_the_same_database_byte_for_byte(database, cluster, tmp_path):
    db, sources = database
    out = _tactrec("build", *sources, "--out", tmp_path / "db", "--units", "mm", "--quiet", "--cluster", cluster[0])
    assert out.returncode == 0, out.stderr
    local = {p.name: p.read_bytes() for p in sorted(db.iterdir())}
    spread = {p.name: p.read_bytes() for p in sorted((tmp_path / "db").iterdir())}
    assert sorted(spread) == sorted(local) and len(local) == len(sources) + 1
    assert [name for name in local if spread[name] != local[name]] == []


def test_without_cluster_nothing_of_dask_is_imported(database, touches):
    db, _ = database
    code = ("import sys; from tactrec.cli import main; main(['recognize', sys.argv[1], '--db', sys.argv[2], "
            "'--quiet']); print(sorted(m for m in ('dask', 'distributed') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, str(touches[0]), str(db)], capture_output=True, text=True,
                         env=_env(), timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"


def _answer(serve, client, victim: str | None, process) -> tuple[dict, bool]:
    """The answer to the request just sent to ``serve``, killing the worker ``victim`` (SIGKILL) if the
    scheduler shows one of the request's tasks on it first: ``(answer, killed)``."""
    while victim is not None:
        if client.processing(workers=[victim]).get(victim):
            process.send_signal(signal.SIGKILL)
            break
        if select.select([serve.stdout], [], [], 0.005)[0]:
            return json.loads(serve.stdout.readline()), False
    return json.loads(serve.stdout.readline()), victim is not None


def test_a_worker_killed_mid_request_loses_no_request_and_changes_no_answer(database, touches, tmp_path):
    """``tactrec serve --cluster``: one worker is killed (SIGKILL) while a request's task runs on it, and
    every answer is the one process's; then the other is killed mid-request, and that request is
    answered with the models that could not be searched, and the service ends with status 3."""
    from distributed import Client

    db, _ = database
    touched = [json.loads(p.read_text()) for p in touches]
    one = _tactrec("serve", "--db", db, "--quiet",
                   stdin="".join(json.dumps({"id": k, "recognize": t}) + "\n" for k, t in enumerate(touched)))
    assert one.returncode == 0, one.stderr
    expected = [dict(a, id=None) for a in _answers(one.stdout)]
    with _cluster(tmp_path / "dask") as (address, workers), Client(address, timeout=10, set_as_default=False) as client:
        serve = subprocess.Popen([sys.executable, "-m", "tactrec", "serve", "--db", str(db), "--quiet", "--cluster",
                                  address], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True, env=_env())
        try:
            victims, answered, killed_at = list(workers.items()), [], []
            for k in range(3 * len(touched)):
                # the first worker from the second request on; the other once every touch ran on it alone
                victim, process = None, None
                if (not killed_at and k >= 1) or (len(killed_at) == 1 and k >= killed_at[0] + len(touched)):
                    victim, process = victims[len(killed_at)]
                serve.stdin.write(json.dumps({"id": k, "recognize": touched[k % len(touched)]}) + "\n")
                serve.stdin.flush()
                answer, killed = _answer(serve, client, victim, process)
                answered.append(answer)
                killed_at += [k] if killed else []
                if "error" in answer:
                    break
            serve.stdin.close()
            status = serve.wait(timeout=60)
            stderr = serve.stderr.read()
        finally:
            if serve.poll() is None:
                serve.kill()
    assert len(killed_at) == 2 and killed_at[1] >= killed_at[0] + len(touched), killed_at
    survived = answered[:killed_at[1]]
    assert [dict(without_timings(a), id=None) for a in survived] == \
        [expected[k % len(touched)] for k in range(len(survived))]
    last = answered[-1]
    assert last["id"] == killed_at[1] and "could not be searched" in last["error"] and last["unavailable"]
    assert set(last["unavailable"]) <= {r["model"] for r in expected[0]["ranking"]}
    assert status == 3 and stderr.count("\n") == 1 and "could not be searched on the cluster" in stderr, stderr
