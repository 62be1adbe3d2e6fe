"""`mocapedit batch`: many shots on dask.distributed, byte for byte what single solves write.

The cluster tests start a real `dask scheduler` and two `dask worker` processes on the
loopback address; each stops by itself (the scheduler after an idle minute, the workers
when their scheduler is gone) and is stopped at the end of the test.
"""
from __future__ import annotations

import json
import os
import signal
import socket
import threading
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mocapedit.pipeline import batch
from mocapedit.data import examples, gestures, walker
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve

from conftest import run_cli
from solve.test_layering import add_clip, add_layer

CROWD = "/World/Crowd"
BIN = Path(sys.executable).parent


def _shot(folder: Path, name: str, late: float, broken: bool = False) -> Path:
    """Three walkers; one frame of the first plays ``late`` time codes late, the second is pinned
    and moved. ``broken`` adds a constraint on a missing agent."""
    clip = walker.walk(frames=48, name="walk")
    specs = [examples.AgentSpec(f"a{i}", clip, (3.0 * i, 0, 0), 0.0, 2.0 * i) for i in range(3)]
    path = folder / f"{name}.usda"
    stage = examples.build_crowd_stage(path, specs, clips_dir=folder / "clips")
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/a0", 24, 24.0 + late)
    examples.add_position_constraint(stage, "/Edits/start", f"{CROWD}/a1", 0, (3.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/end", f"{CROWD}/a1", 47, (4.0, 0.0, 3.0))
    if broken:
        examples.add_time_constraint(stage, "/Edits/nobody", f"{CROWD}/nobody", 3, 5.0)
    stage.GetRootLayer().Save()
    return path


@pytest.fixture
def shots(tmp_path):
    folder = tmp_path / "shots"
    folder.mkdir()
    return [_shot(folder, "s1", 3.5), _shot(folder, "s2", -2.0), _shot(folder, "bad", 1.0, broken=True)]


def _single(shot: Path, outdir: Path) -> bytes:
    out = outdir / batch.output_name(str(shot), ".edits.usdc")
    solve(str(shot), output=str(out))
    return out.read_bytes()


def test_the_plan_is_checked_before_any_work(tmp_path, shots):
    with pytest.raises(MocapEditError, match=r"nowhere\.usda: no such shot file"):
        batch.plan([str(shots[0]), str(tmp_path / "nowhere.usda")], str(tmp_path / "out"))
    other = tmp_path / "other"
    other.mkdir()
    twin = _shot(other, "s1", 1.0)
    with pytest.raises(MocapEditError, match=r"would both write .*s1\.edits\.usdc"):
        batch.plan([str(shots[0]), str(twin)], str(tmp_path / "out"))
    with pytest.raises(MocapEditError, match="would overwrite an input shot"):
        batch.plan([str(shots[0])], str(shots[0].parent), suffix=".usda")
    with pytest.raises(MocapEditError, match=r"s1\.edits\.txt"):   # not a layer USD can write
        batch.plan([str(shots[0])], str(tmp_path / "out"), suffix=".edits.txt")
    with pytest.raises(MocapEditError, match=r"--suffix '/\.\./x\.usda': names a folder"):   # outside OUTDIR
        batch.plan([str(shots[0])], str(tmp_path / "out"), suffix="/../x.usda")
    # From the command line: exit 1, a message, nothing written, no cluster started.
    out = tmp_path / "out"
    started = time.perf_counter()
    proc = run_cli("batch", shots[0], tmp_path / "nowhere.usda", "-o", out)
    assert proc.returncode == 1 and "no such shot file" in proc.stderr and "Traceback" not in proc.stderr
    proc = run_cli("batch", shots[0], twin, "-o", out)
    assert proc.returncode == 1 and "would both write" in proc.stderr
    assert not out.exists() and time.perf_counter() - started < 10


def test_no_output_of_a_batch_overwrites_a_file_any_shot_uses(tmp_path, shots):
    """The summary and every edits layer are checked against every file every shot reads
    (its clips too), and against each other, before any work: a summary named like a shot,
    a shot's clip or an edits layer was written over it after the batch had run."""
    out = tmp_path / "out"
    clip = next((shots[0].parent / "clips").glob("*.usd*"))
    for target in (shots[1], clip, out / "s1.edits.usdc"):
        before = target.read_bytes() if target.exists() else None
        with pytest.raises(MocapEditError, match="summary"):
            batch.plan([str(shots[0]), str(shots[1])], str(out), summary=str(target))
        proc = run_cli("batch", shots[0], shots[1], "-o", out, "--summary", target, "--workers", "1")
        assert proc.returncode == 1 and "--summary" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
        assert (target.read_bytes() if target.exists() else None) == before
        assert not out.exists()
    # A folder as the summary, or one that cannot be made, is refused before any work too.
    with pytest.raises(MocapEditError, match="--summary .*folder"):
        batch.plan([str(shots[0])], str(out), summary=str(tmp_path))
    if os.path.isdir("/proc/self"):   # a file system that makes no folders, whatever the permissions
        with pytest.raises(MocapEditError, match="cannot make the folder /proc/mocapedit-nowhere in /proc"):
            batch.plan([str(shots[0])], "/proc/mocapedit-nowhere")
    # An edits layer of one shot named like a file another shot reads: shot "walk" would
    # write clips/walk.usda, the clip s1 plays.
    other = tmp_path / "other"
    other.mkdir()
    walk = _shot(other, clip.stem, 1.0)
    with pytest.raises(MocapEditError, match="names a file the input uses"):
        batch.plan([str(shots[0]), str(walk)], str(clip.parent), suffix=clip.suffix)


def test_an_unreachable_scheduler_is_a_clear_error_within_ten_seconds(tmp_path, shots):
    with socket.socket() as s:   # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    started = time.perf_counter()
    proc = run_cli("batch", shots[0], "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}")
    assert time.perf_counter() - started < 10
    assert proc.returncode == 1, proc.stderr
    assert f"cannot reach a Dask scheduler" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("answer", [None, b"HTTP/1.0 400 Bad Request\r\n\r\n"], ids=["silent", "not dask"])
def test_a_scheduler_address_that_is_not_a_dask_scheduler_is_a_clear_error_within_ten_seconds(tmp_path, shots, answer):
    """A port that accepts and never answers (it hung for ever) or answers with something else
    than Dask (a web server, the dashboard's port by mistake: it said "out of memory")."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    port = server.getsockname()[1]
    held = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            if answer is not None:
                conn.sendall(answer)
                conn.close()
            else:
                held.append(conn)

    threading.Thread(target=serve, daemon=True).start()
    try:
        started = time.perf_counter()
        proc = run_cli("batch", shots[0], "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}",
                       timeout=30)
        assert time.perf_counter() - started < 10
    finally:
        server.close()
        for conn in held:
            conn.close()
    assert proc.returncode == 1, proc.stderr
    assert "Dask scheduler" in proc.stderr and "check the address" in proc.stderr, proc.stderr
    assert "memory" not in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "out").exists()


def test_solve_shot_reports_failures_and_skips_up_to_date_outputs(tmp_path, shots):
    jobs = batch.plan([str(s) for s in shots], str(tmp_path / "out"))
    options = {"guides": True, "collisions": None}
    results = [batch.solve_shot(job, options) for job in jobs]
    assert [r.status for r in results] == ["solved", "solved", "failed"]
    assert "</Edits/nobody>" in results[2].error and not os.path.exists(jobs[2].output)
    assert results[0].figures["editedAgents"] == 2 and results[0].figures["worstHardResidual"] < 1e-6
    again = [batch.solve_shot(job, options) for job in jobs[:2]]
    assert [r.status for r in again] == ["skipped", "skipped"]
    # Other options, or another input, solve again.
    assert batch.solve_shot(jobs[0], {"guides": False, "collisions": None}).status == "solved"
    _shot(shots[1].parent, "s2", -1.0)
    assert batch.solve_shot(jobs[1], options).status == "solved"


def test_a_shot_without_agents_keeps_its_note_in_the_batch(tmp_path, shots):
    """An empty stage among shots: solved, and the note solve prints ("the stage has no agents")
    is in its summary entry and on stderr (the batch said only "solved", agents: 0)."""
    empty = tmp_path / "empty.usda"
    empty.write_text("#usda 1.0\n")
    jobs = batch.plan([str(shots[0]), str(empty)], str(tmp_path / "out"))
    result = batch.solve_shot(jobs[1], {"guides": True, "collisions": None})
    assert result.status == "solved" and any("no agents" in n for n in result.notes), result
    assert not any("no agents" in n for n in batch.solve_shot(jobs[0], {"guides": True, "collisions": None}).notes)
    proc = run_cli("batch", shots[0], empty, "-o", tmp_path / "cli", "--workers", "1")
    assert proc.returncode == 0, proc.stderr
    assert "empty.usda" in proc.stderr and "no agents" in proc.stderr
    summary = json.loads((tmp_path / "cli" / batch.SUMMARY).read_text())
    entry = next(r for r in summary["shots"] if r["shot"].endswith("empty.usda"))
    assert any("no agents" in n for n in entry["notes"])


@pytest.fixture
def cluster(tmp_path):
    """A `dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    info = tmp_path / "scheduler.json"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(info), "--idle-timeout", "120"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                              start_new_session=True)]
    deadline = time.time() + 60
    while not info.exists() and time.time() < deadline:
        time.sleep(0.2)
    address = json.loads(info.read_text())["address"]
    for i in range(2):
        procs.append(subprocess.Popen(
            [str(BIN / "dask"), "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
             "--death-timeout", "30", "--name", f"w{i}", "--local-directory", str(tmp_path / f"w{i}")],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True))
    from distributed import Client
    with Client(address, timeout=30) as client:
        client.wait_for_workers(2, timeout=60)
    yield address
    for p in reversed(procs):
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


@pytest.mark.slow
def test_a_batch_on_a_running_cluster_writes_what_single_solves_write(tmp_path, shots, cluster):
    single, out = tmp_path / "single", tmp_path / "out"
    expected = {s.name: _single(s, single) for s in shots[:2]}
    proc = run_cli("batch", *shots, "-o", out, "--scheduler", cluster)
    assert proc.returncode == 1, proc.stderr          # one shot failed
    assert "Traceback" not in proc.stderr
    assert "3 remaining" not in proc.stderr and "0 remaining" in proc.stderr
    for shot in shots[:2]:
        assert (out / batch.output_name(str(shot), ".edits.usdc")).read_bytes() == expected[shot.name]
    summary = json.loads((out / batch.SUMMARY).read_text())
    assert (summary["solved"], summary["skipped"], summary["failed"]) == (2, 0, 1)
    by_shot = {Path(r["shot"]).name: r for r in summary["shots"]}
    assert "</Edits/nobody>" in by_shot["bad.usda"]["error"]
    assert by_shot["s1.usda"]["figures"]["worstHardResidual"] < 1e-6
    # Nothing half-written: no temporary files are left beside the outputs.
    assert sorted(p.name for p in out.iterdir()) == sorted(["s1.edits.usdc", "s2.edits.usdc", batch.SUMMARY])
    # A re-run skips what is up to date.
    proc = run_cli("batch", *shots[:2], "-o", out, "--scheduler", cluster)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / batch.SUMMARY).read_text())
    assert (summary["solved"], summary["skipped"]) == (0, 2)


@pytest.mark.slow
def test_a_batch_on_a_local_cluster(tmp_path, shots):
    single, out = tmp_path / "single", tmp_path / "out"
    expected = _single(shots[0], single)
    proc = run_cli("batch", *shots[:2], "-o", out, "--workers", "2")
    assert proc.returncode == 0, proc.stderr
    assert (out / "s1.edits.usdc").read_bytes() == expected
    assert "2 done, 0 failed, 0 remaining" in proc.stderr


def test_a_local_cluster_starts_when_the_dashboard_port_is_taken():
    # Dask's scheduler serves HTTP on 8787 unless told otherwise; a dashboard or another batch
    # on the same machine holds that port, which must not stop a batch.
    holder = socket.socket()
    try:
        holder.bind(("0.0.0.0", 8787))
        holder.listen()
    except OSError:
        pass  # already held by another process: the same situation
    try:
        client, cluster = batch.connect(None, 1)
        try:
            assert client.submit(sum, [1, 2], pure=False).result(timeout=60) == 3
        finally:
            client.close()
            cluster.close()
    finally:
        holder.close()


# ---- a shot split over workers by path component ---------------------------------------------

@pytest.mark.slow
def test_a_batch_stopped_by_sigterm_names_every_edits_layer_it_left(tmp_path):
    """SIGTERM while shots run: the workers' shots that finish writing are whole, and the
    message names each of them (it said "nothing was written" over two complete layers)."""
    folder = tmp_path / "shots"
    folder.mkdir()
    shots = [_shot(folder, f"s{i}", 1.0 + i) for i in range(6)]
    out = tmp_path / "out"
    exe = Path(sys.executable).with_name("mocapedit")
    proc = subprocess.Popen([str(exe), "batch", *map(str, shots), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(out.glob("*.edits.usdc")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the batch ended before the signal")
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err
    left = sorted(out.glob("*.edits.usdc"))
    assert left, err
    message = [l for l in err.splitlines() if "stopped by signal" in l]
    assert message and "nothing was written" not in message[-1], err
    for layer in left:
        assert str(layer) in message[-1], (layer, message[-1])
        assert batch.output_name(str(folder / layer.name.replace(".edits.usdc", ".usda")), ".edits.usdc") == layer.name
    # Whole layers only, no temporaries.
    assert all(".mocapedit~" not in p.name for p in out.iterdir())


def _components_shot(folder: Path, contradiction: bool = False) -> Path:
    """Nine walkers, five path components: a0 tied to a1 by a relative constraint; a group
    a2-a4 with a pin; a5, a6 and a8 pinned alone (a5 also late); a7 untouched.
    ``contradiction`` pins a6's frame 10 to two places."""
    clip = walker.walk(frames=48, name="walk")
    specs = [examples.AgentSpec(f"a{i}", clip, (3.0 * (i % 3), 0, 3.0 * (i // 3)), 0.0, float(i)) for i in range(9)]
    path = folder / ("contradiction.usda" if contradiction else "components.usda")
    stage = examples.build_crowd_stage(path, specs, clips_dir=folder / "clips")
    pins = [("a0_end", 0, 47, (1.0, 0.0, 4.0)), ("a2_end", 2, 47, (7.0, 0.0, 5.0))]
    pins += [(f"a{i}_end", i, 40, (3.0 * (i % 3) - 1.0, 0.0, 3.0 * (i // 3) + 2.5)) for i in (5, 6, 8)]
    pins += [(f"a{i}_start", i, 0, (3.0 * (i % 3), 0.0, 3.0 * (i // 3))) for i in (0, 2, 5, 6, 8)]
    if contradiction:
        pins += [("a6_here", 6, 10, (0.0, 0.0, 6.0)), ("a6_there", 6, 10, (2.0, 0.0, 6.0))]
    for name, i, frame, position in pins:
        examples.add_position_constraint(stage, f"/Edits/{name}", f"{CROWD}/a{i}", frame, position)
    examples.add_relative_constraint(stage, "/Edits/a1_beside", f"{CROWD}/a1", 30, f"{CROWD}/a0", 30, (1.0, 0.0, 0.0))
    examples.add_group(stage, "/Edits/group", [f"{CROWD}/a{i}" for i in (2, 3, 4)])
    examples.add_time_constraint(stage, "/Edits/a5_late", f"{CROWD}/a5", 24, 30.0)
    phone = gestures.phone_call(frames=48)   # a layered pose edit, which foot locking applies first
    add_clip(stage, "/Layers/Phone", phone.joints, phone.translations, phone.rotations)
    add_layer(stage, "/Layers/Call", [f"{CROWD}/a8"], "/Layers/Phone", "Spine", "additive",
              weight={4: 0.0, 12: 1.0}, reference="restPose")
    stage.GetRootLayer().Save()
    return path


@pytest.fixture
def component_shots(tmp_path):
    (tmp_path / "split").mkdir()
    return tuple(_components_shot(tmp_path / "split", contradiction) for contradiction in (False, True))


@pytest.mark.slow
def test_a_shot_split_by_component_on_a_local_cluster_gives_the_single_solves_bytes(tmp_path, component_shots):
    shot, bad = map(str, component_shots)
    client, cluster = batch.connect(None, 2)
    with cluster, client:
        for collisions in (None, True):
            single, split = tmp_path / f"single-{collisions}.usdc", tmp_path / f"split-{collisions}.usdc"
            whole = solve(shot, output=str(single), collisions=collisions)
            pool = batch.DaskComponents(client)
            parts = solve(shot, output=str(split), collisions=collisions, components=pool)
            stats = whole.report.stats
            assert stats.path_components == 5 and stats.foot_locked_agents >= 3 and stats["layeredAgents"] == 1
            # Up to two runs per worker for the path pass, and as many for foot locking.
            assert pool.chunks == 4 and 4 <= pool.tasks <= 8
            assert split.read_bytes() == single.read_bytes()
            assert parts.report.to_layer_dict() == whole.report.to_layer_dict()
        # A contradiction in one component is the error the single solve gives, and nothing is written.
        with pytest.raises(MocapEditError) as single_error:
            solve(bad, output=str(tmp_path / "bad-single.usdc"))
        with pytest.raises(MocapEditError) as split_error:
            solve(bad, output=str(tmp_path / "bad-split.usdc"), components=batch.DaskComponents(client))
    assert "</Edits/a6_here>" in str(split_error.value) and str(split_error.value) == str(single_error.value)
    assert split_error.value.prim == single_error.value.prim == "/Edits/a6_here"
    assert not (tmp_path / "bad-split.usdc").exists()


@pytest.mark.slow
def test_split_components_on_a_running_cluster_writes_what_single_solves_write(tmp_path, component_shots, cluster):
    shot = component_shots[0]
    expected = _single(shot, tmp_path / "single")
    out = tmp_path / "out"
    proc = run_cli("batch", shot, "-o", out, "--scheduler", cluster, "--split-components")
    assert proc.returncode == 0, proc.stderr
    assert (out / batch.output_name(str(shot), ".edits.usdc")).read_bytes() == expected
    summary = json.loads((out / batch.SUMMARY).read_text())
    assert summary["shots"][0]["status"] == "solved" and summary["shots"][0]["componentTasks"] >= 2
    # Without the switch the shot's own task solves its components.
    proc = run_cli("batch", shot, "-o", out, "--scheduler", cluster, "--force")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((out / batch.SUMMARY).read_text())["shots"][0]["componentTasks"] == 0
    assert (out / batch.output_name(str(shot), ".edits.usdc")).read_bytes() == expected


def _worker_environ():
    return {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS")}


def test_a_local_clusters_workers_reuse_freed_memory(monkeypatch):
    # Dask's default MALLOC_TRIM_THRESHOLD_ makes glibc map every large array afresh (a
    # 1,000-agent solve took 388k page faults instead of 183k, 0.9 s more system time); numpy
    # stays on one thread per worker.
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    client, cluster = batch.connect(None, 1)
    with cluster, client:
        (environ,) = client.run(_worker_environ).values()
    assert environ == {"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": "1"}


def _worker_threads():
    from mocapedit.solve import threads
    return os.environ.get(threads.ENVIRONMENT), threads.budget()


def test_a_local_clusters_workers_share_the_cores_between_their_solver_threads(monkeypatch):
    # Two workers on two cores, each solving on two threads, took 6% longer per shot than on
    # one thread each; a budget the caller sets is theirs.
    monkeypatch.delenv("MOCAPEDIT_THREADS", raising=False)
    cores = len(os.sched_getaffinity(0))
    client, cluster = batch.connect(None, 2)
    with cluster, client:
        seen = set(client.run(_worker_threads).values())
    share = max(1, cores // 2)
    assert seen == {(str(share), share)}
    assert "MOCAPEDIT_THREADS" not in os.environ, "the workers' share is theirs, not this process's"
    monkeypatch.setenv("MOCAPEDIT_THREADS", "3")
    client, cluster = batch.connect(None, 1)
    with cluster, client:
        assert set(client.run(_worker_threads).values()) == {("3", 3)}
