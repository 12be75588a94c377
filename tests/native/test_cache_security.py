"""The native cache loads only what this user's gnipy compiled (gnipy.private_cache): every attack
on the cache folder ends in a correct run of code compiled for it, with no crash.

Attacks: an object that calls system() planted at a program's key (in the old format: the object
and its SHA-256; with a tag made with another secret); two programs' entries swapped; a folder
writable by others (0777, 1777, group-writable); a folder or an entry that is a link; another
owner (a monkeypatched `os.geteuid`, and as root a real `chown`); an unusable secret; a write that
fails (a full disk, Ctrl-C, RLIMIT_FSIZE) and temporaries of dead processes; random damage of an
entry (hypothesis). The programs are the toy steps below, whose results are exact sums; each build
starts from an empty engine memory (`gnipy.native.engine._ENGINES`), so it reads the disk."""

import errno
import hashlib
import hmac
import os
import stat
import subprocess
import sys
import textwrap
import threading
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gnipy import private_cache, private_folder
from gnipy.compilation import enable_compilation_cache
from gnipy.native import engine as native_engine
from gnipy.native import program
from gnipy.native.program import build_loop
from gnipy.private_cache import SECRET_NAME, PrivateCache
from gnipy.private_folder import CacheWarning, private_directory
from test_program import _carry, _toy_step

# a warning where none is expected fails the test (the tests that expect one record them)
pytestmark = pytest.mark.filterwarnings("error::gnipy.private_folder.CacheWarning")

HERE = os.path.dirname(os.path.abspath(__file__))
H = 0.25
BLOCKS = [2, 0, 3]
START = np.array([0.0, 0.0, 0, -1, 0, 0, 0])


def _other_step(carry, h):
    """x ← x + h·(2, 1): another program with the toy step's carry (a swapped entry would run)."""
    state, k, fail_k, fail_res, it_tot, it_max = carry
    return (state + h * jnp.array([2.0, 1.0]), k + 1, fail_k, fail_res, it_tot + 1, jnp.maximum(it_max, 1))


STEPS = {"toy": _toy_step, "other": _other_step}
# the exact results of 5 steps of h = 1/4 from (0, 0), saved after blocks of 2, 0 and 3 steps:
# the toy step x₁ = h²(0 + 1 + 2 + 3 + 4); the other step (2h·5, h·5)
EXPECTED = {"toy": ([0.5, 0.5, 1.25], [1.25, 0.625, 5, -1]), "other": ([1.0, 1.0, 2.5], [2.5, 1.25, 5, -1])}


def _build(which="toy"):
    """Build a program with an empty engine memory (so the disk cache is asked), and check that
    it computes its own exact results; returns where its code came from."""
    native_engine._ENGINES.clear()
    loop = build_loop(STEPS[which], _carry([0.0, 0.0]), H)
    carry, saved = loop.run(START, H, BLOCKS)
    saved_x0, carry_head = EXPECTED[which]
    np.testing.assert_array_equal(saved[:, 0], saved_x0)
    np.testing.assert_array_equal(carry[:4], carry_head)
    return loop.source


@pytest.fixture
def native(tmp_path, monkeypatch):
    """The native cache folder of a fresh `GNIPY_CACHE_DIR` (not yet created); the engine memory
    and the warnings already given are this test's own."""
    monkeypatch.setenv("GNIPY_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("GNIPY_NATIVE_CACHE", raising=False)
    monkeypatch.setattr(native_engine, "_ENGINES", {})
    monkeypatch.setattr(private_folder, "_WARNED", set())
    return tmp_path / "cache" / "native"


def _entries(folder):
    """The cache entries of `folder`: {program: path}, found by building each program once in a
    private folder (the first build compiles and writes)."""
    out = {}
    for which in STEPS:
        before = set(folder.glob("*.o")) if folder.exists() else set()
        assert _build(which) == "compiled"
        (new,) = set(folder.glob("*.o")) - before
        out[which] = new
    return out


def _listing(folder):
    """Every name in `folder` with its bytes (None for a link or a folder)."""
    return {p.name: (None if p.is_symlink() or p.is_dir() else p.read_bytes()) for p in sorted(folder.iterdir())}


def _cache_warnings(records):
    return [str(w.message) for w in records if issubclass(w.category, CacheWarning)]


def _malicious_object(marker):
    """Valid object code whose `gnipy_run` and `gnipy_run_batch` call system("touch MARKER")."""
    cmd = f"touch {marker}".encode() + b"\0"
    text = "".join(f"\\{b:02X}" for b in cmd)
    sig = "ptr %c, double %h, ptr %l, i64 %n, ptr %s"
    ir = textwrap.dedent(f"""
        @cmd = private constant [{len(cmd)} x i8] c"{text}"
        declare i32 @system(ptr)
        define void @gnipy_run({sig}) {{
          %r = call i32 @system(ptr @cmd)
          ret void
        }}
        define void @gnipy_run_batch({sig}, i64 %a, i64 %b) {{
          %r = call i32 @system(ptr @cmd)
          ret void
        }}
    """)
    return native_engine.compile_ir(ir)


def test_the_planted_object_runs_system_when_loaded(tmp_path):
    """The attack object of the tests below does what D1's did: loaded, it runs a command."""
    marker = tmp_path / "ran"
    llvm = native_engine.llvm_binding()
    engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), native_engine.target_machine())
    engine.add_object_file(llvm.ObjectFileRef.from_data(_malicious_object(marker)))
    engine.finalize_object()
    program._SINGLE(engine.get_function_address("gnipy_run"))(None, 0.0, None, 0, None)
    assert marker.exists()


@pytest.mark.parametrize("form", ["sha256", "other-secret", "other-key"])
def test_a_planted_object_is_not_loaded(native, tmp_path, form):
    """An object that calls system() at the toy program's key: followed by its own SHA-256 (the old
    format, D1), by a tag made with another user's secret, or by a tag made with this user's
    secret for another key (as if gnipy had written it for another program)."""
    own = _entries(native)["toy"]
    mine = own.read_bytes()
    key = own.name.removesuffix(".o")
    marker = tmp_path / "ran"
    obj = _malicious_object(marker)
    if form == "sha256":
        planted = obj + hashlib.sha256(obj).digest()
    elif form == "other-secret":
        planted = obj + hmac.new(os.urandom(32), key.encode() + b"\0" + obj, hashlib.sha256).digest()
    else:
        with PrivateCache(native) as cache:
            planted = obj + cache.tag("0" * 64, obj)
    own.write_bytes(planted)
    assert _build() == "compiled"
    assert not marker.exists()
    assert own.read_bytes() == mine  # replaced by the program's own entry, which loads next time
    assert _build() == "disk"


def test_swapped_entries_are_compiled_again(native):
    """D2: two programs' valid entries exchanged: each program compiles its own code again (a
    loaded swap would give the other program's sums), and the entries are put right."""
    entries = _entries(native)
    toy, other = entries["toy"].read_bytes(), entries["other"].read_bytes()
    entries["toy"].write_bytes(other)
    entries["other"].write_bytes(toy)
    assert _build("toy") == "compiled" and _build("other") == "compiled"
    assert entries["toy"].read_bytes() == toy and entries["other"].read_bytes() == other
    assert _build("toy") == "disk" and _build("other") == "disk"


@pytest.mark.parametrize("mode", [0o777, 0o1777, 0o770, 0o702], ids=lambda m: f"{m:04o}")
def test_a_folder_others_can_write_is_refused(native, tmp_path, mode):
    """A folder writable by others (a shared 1777 one as in D1) or by its group is not used, even
    though it holds a secret and an entry that would authenticate: the program is compiled in
    memory, with one warning for the folder, and nothing in it is read or written."""
    _entries(native)
    os.chmod(native, mode)
    before = _listing(native)
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        assert _build("toy") == "compiled" and _build("other") == "compiled"
    (message,) = _cache_warnings(records)
    assert str(native) in message and f"mode {mode:04o}" in message and "writable by" in message
    assert "GNIPY_CACHE_DIR" in message and "GNIPY_NATIVE_CACHE=0" in message
    assert _listing(native) == before and stat.S_IMODE(native.stat().st_mode) == mode


def test_a_linked_folder_is_refused(native, tmp_path):
    """The native folder is a link to a private folder with a secret and valid entries: not
    followed (compiled in memory, one warning), and the folder it points to is left as it was."""
    _entries(native)
    real = tmp_path / "real"
    native.rename(real)
    native.symlink_to(real)
    before = _listing(real)
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        assert _build("toy") == "compiled" and _build("other") == "compiled"
    (message,) = _cache_warnings(records)
    assert str(native) in message and "symbolic link" in message
    assert _listing(real) == before and native.is_symlink()


@pytest.mark.parametrize("kind", ["symlink", "hardlink", "writable", "fifo", "directory"])
def test_an_entry_that_is_not_a_plain_file_of_ours_is_not_opened(native, tmp_path, kind):
    """An entry that gnipy never writes in its folder (a link to a valid entry, a second hard link,
    a file others may write, a FIFO that would block a reader, a directory): not followed or
    opened; compiled in memory with one warning, and replaced by gnipy's own entry where it can
    be (the name, never what a link points to)."""
    own = _entries(native)["toy"]
    valid = own.read_bytes()
    target = tmp_path / "valid.o"
    if kind == "symlink":
        own.rename(target)
        own.symlink_to(target)
    elif kind == "hardlink":
        os.link(own, target)
    elif kind == "writable":
        os.chmod(own, 0o666)
    elif kind == "fifo":
        own.unlink()
        os.mkfifo(own)
    else:
        own.unlink()
        own.mkdir()
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        assert _build() == "compiled"
    (message,) = _cache_warnings(records)
    assert str(native) in message and own.name in message
    if kind == "directory":  # a directory cannot be renamed over: left, and refused every time
        assert own.is_dir() and _build() == "compiled"
        return
    assert own.is_file() and not own.is_symlink() and own.stat().st_nlink == 1 and own.read_bytes() == valid
    assert stat.S_IMODE(own.stat().st_mode) == 0o600
    if kind in ("symlink", "hardlink"):
        assert target.read_bytes() == valid
    assert _build() == "disk"


def test_a_folder_of_another_user_is_refused(native, monkeypatch):
    """Another owner: `os.geteuid` made to answer another uid, so the folder (with a secret and
    valid entries) is someone else's: refused, compiled in memory, one warning. As root (as in
    CI) also for real: the folder given to uid 65534, and then an entry of uid 65534."""
    toy = _entries(native)["toy"]
    before = _listing(native)
    real = os.geteuid()
    with monkeypatch.context() as m:
        m.setattr(os, "geteuid", lambda: real + 1)
        with warnings.catch_warnings(record=True) as records:
            warnings.simplefilter("always")
            assert _build("toy") == "compiled" and _build("other") == "compiled"
    (message,) = _cache_warnings(records)
    assert str(native) in message and f"uid {real}" in message and "not to you" in message
    assert _listing(native) == before
    assert _build() == "disk"  # the real owner's folder is fine
    if real == 0:
        monkeypatch.setattr(private_folder, "_WARNED", set())
        os.chown(native, 65534, 65534)
        with warnings.catch_warnings(record=True) as records:
            warnings.simplefilter("always")
            assert _build() == "compiled"
        (message,) = _cache_warnings(records)
        assert "uid 65534" in message and _listing(native) == before
        os.chown(native, 0, 0)
        os.chown(toy, 65534, 65534)
        monkeypatch.setattr(private_folder, "_WARNED", set())
        with warnings.catch_warnings(record=True) as records:
            warnings.simplefilter("always")
            assert _build() == "compiled"
        (message,) = _cache_warnings(records)
        assert toy.name in message and "uid 65534" in message
        assert toy.stat().st_uid == 0 and toy.read_bytes() == before[toy.name]


@pytest.mark.parametrize("damage", ["mode 0644", "mode 0640", "31 bytes", "33 bytes", "empty", "symlink",
                                    "directory"])
def test_an_unusable_secret_refuses_the_folder(native, tmp_path, damage):
    """The secret readable by others, of the wrong length, a link or not a file: the folder is
    refused with a warning that names the secret and says to remove it; nothing is written."""
    _entries(native)
    secret = native / SECRET_NAME
    key = secret.read_bytes()
    if damage.startswith("mode"):
        os.chmod(secret, int(damage.split()[1], 8))
    elif damage == "symlink":
        (tmp_path / "key").write_bytes(key)
        os.chmod(tmp_path / "key", 0o600)
        secret.unlink()
        secret.symlink_to(tmp_path / "key")
    elif damage == "directory":
        secret.unlink()
        secret.mkdir()
    else:
        secret.write_bytes({"31 bytes": key[:31], "33 bytes": key + b"x", "empty": b""}[damage])
    before = _listing(native)
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        assert _build("toy") == "compiled" and _build("other") == "compiled"
    (message,) = _cache_warnings(records)
    assert str(native) in message and SECRET_NAME in message
    if damage not in ("symlink", "directory"):
        assert "remove it" in message
    assert _listing(native) == before


def test_two_processes_making_the_secret_agree(tmp_path, monkeypatch):
    """The secret is made whole and never replaced: when another process makes it between our
    look and our link, ours is dropped and theirs read; many threads at once get one secret."""
    folder = tmp_path / "f"
    winner = os.urandom(32)
    real_link = os.link

    def link_after_another(src, dst, **kwargs):
        fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600, dir_fd=kwargs["dst_dir_fd"])
        os.write(fd, winner)
        os.close(fd)
        return real_link(src, dst, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(os, "link", link_after_another)
        with PrivateCache(folder) as cache:
            assert cache._secret == winner
    assert sorted(p.name for p in folder.iterdir()) == [SECRET_NAME]

    folder = tmp_path / "g"
    secrets_seen, barrier = [], threading.Barrier(8)

    def open_one():
        barrier.wait()
        with PrivateCache(folder) as cache:
            secrets_seen.append(cache._secret)

    threads = [threading.Thread(target=open_one) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(secrets_seen) == 8 and len(set(secrets_seen)) == 1
    assert (folder / SECRET_NAME).read_bytes() == secrets_seen[0]
    assert sorted(p.name for p in folder.iterdir()) == [SECRET_NAME]
    assert stat.S_IMODE((folder / SECRET_NAME).stat().st_mode) == 0o600


def test_folders_are_made_private(tmp_path):
    """A missing cache folder and the missing folders above it are made with mode 0700; an
    existing private folder (0755 from an older gnipy) is used as it is."""
    fd = private_directory(tmp_path / "a" / "b" / "c")
    os.close(fd)
    for p in (tmp_path / "a", tmp_path / "a" / "b", tmp_path / "a" / "b" / "c"):
        assert stat.S_IMODE(p.stat().st_mode) == 0o700
    old = tmp_path / "old"
    old.mkdir(mode=0o755)
    os.chmod(old, 0o755)
    os.close(private_directory(old))
    assert stat.S_IMODE(old.stat().st_mode) == 0o755


def test_an_entry_is_tied_to_its_key(tmp_path):
    cache = PrivateCache(tmp_path / "f")
    try:
        assert cache.write("x.o", "key one", b"data")
        assert cache.read("x.o", "key one") == b"data"
        assert cache.read("x.o", "key two") is None
        assert cache.read("missing.o", "key one") is None
        for bad in (".key", "../x.o", "a/b", ""):
            with pytest.raises(ValueError, match="not the name of a cache entry"):
                cache.write(bad, "key one", b"data")
    finally:
        cache.close()
    with PrivateCache(tmp_path / "g") as other:  # another folder (another user's secret): not ours
        os.link(tmp_path / "f" / "x.o", tmp_path / "g" / "y.o")
        (tmp_path / "f" / "x.o").unlink()
        assert other.read("y.o", "key one") is None


def test_the_compilation_cache_refuses_a_folder_that_is_not_private(tmp_path, monkeypatch):
    """JAX's cache (opt-in) loads executables too: a folder writable by others, a link, a path that
    cannot be opened, or another user's folder is refused with a warning, and JAX's setting is
    left alone."""
    monkeypatch.setattr(private_folder, "_WARNED", set())
    before = jax.config.jax_compilation_cache_dir
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o1777)
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "private")
    (tmp_path / "private").mkdir(mode=0o700)
    with warnings.catch_warnings(record=True) as records:
        warnings.simplefilter("always")
        assert enable_compilation_cache(shared) is None
        assert enable_compilation_cache(link) is None
        assert enable_compilation_cache(str(tmp_path / "nul\0name")) is None
        monkeypatch.setattr(os, "geteuid", lambda: os.getuid() + 1)
        assert enable_compilation_cache(tmp_path / "private") is None
    messages = _cache_warnings(records)
    assert len(messages) == 4 and all("JAX's compilation cache" in m for m in messages)
    assert "mode 1777" in messages[0] and "symbolic link" in messages[1] and "null" in messages[2]
    assert "not to you" in messages[3] and "nul\\x00name" in messages[2]  # shown escaped
    assert jax.config.jax_compilation_cache_dir == before


def test_a_failed_write_leaves_no_temporary(native, monkeypatch):
    """D3: a write that fails half-way (a full disk) or is interrupted (Ctrl-C) removes its
    temporary file; a full disk is not an error (the run goes on with the compiled code)."""
    PrivateCache(native).close()  # the secret exists: the entry's write is the one that fails
    real_write_all = private_cache._write_all
    calls = []

    def full_disk(fd, data):
        calls.append(len(data))
        real_write_all(fd, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    with monkeypatch.context() as m:
        m.setattr(private_cache, "_write_all", full_disk)
        assert _build() == "compiled"
    assert calls and sorted(p.name for p in native.iterdir()) == [SECRET_NAME]

    def interrupted(fd, data):
        real_write_all(fd, data[:100])
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(private_cache, "_write_all", interrupted)
        with pytest.raises(KeyboardInterrupt):
            _build()
    assert sorted(p.name for p in native.iterdir()) == [SECRET_NAME]
    assert _build() == "compiled" and _build() == "disk"  # and the next write succeeds


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", ""])
    p.wait()
    return p.pid


def test_temporaries_of_dead_processes_are_removed_by_the_next_write(native):
    """A temporary of a process that died (SIGKILL, power loss) goes at the next write, for any
    entry; a running process's temporary and files that are not gnipy's temporaries stay. The
    temporaries of gnipy 0.1 (`tmpXXXXXXXX.tmp`, D3: left for good) carry no process id: they go
    once older than any write takes."""
    from gnipy.private_cache import OLD_TEMPORARY_SECONDS

    entries = _entries(native)
    toy = entries["toy"].name
    for p in entries.values():
        p.unlink()
    dead = _dead_pid()
    stale = [native / f".{toy}.gnipy-{dead}-abcdef123456.tmp", native / f".{'0' * 64}.o.gnipy-{dead}-0123456789ab.tmp",
             native / "tmp8x_3jq0a.tmp"]
    kept = [native / f".{toy}.gnipy-{os.getpid()}-fedcba987654.tmp", native / "tmpk2j3h4g5.tmp", native / "notes.txt"]
    for p in stale + kept:
        p.write_bytes(b"partial")
    old = time.time() - OLD_TEMPORARY_SECONDS - 60
    os.utime(stale[-1], (old, old))  # written by gnipy 0.1 an hour ago; tmpk2j3h4g5.tmp just now
    assert _build() == "compiled"
    assert not any(p.exists() for p in stale) and all(p.exists() for p in kept)
    assert (native / toy).is_file()


def test_a_write_over_the_file_size_limit_in_a_fresh_process(native, tmp_path):
    """D3 for real: RLIMIT_FSIZE below the entry's size (SIGXFSZ ignored, so the write fails with
    EFBIG): the run is correct and compiled, no temporary is left, and a dead process's
    temporary is removed all the same."""
    PrivateCache(native).close()
    stale = native / f".{'1' * 64}.o.gnipy-{_dead_pid()}-abcdef123456.tmp"
    stale.write_bytes(b"partial")
    script = textwrap.dedent(f"""
        import resource, signal, sys
        import numpy as np
        sys.path.insert(0, {HERE!r})
        import gnipy
        from test_cache_security import _build
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1024, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
        print(_build("toy"), _build("other"))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=dict(os.environ),
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["compiled", "compiled"]
    assert sorted(p.name for p in native.iterdir()) == [SECRET_NAME]


def test_no_disk_cache_when_turned_off(native, monkeypatch):
    monkeypatch.setenv("GNIPY_NATIVE_CACHE", "0")
    assert _build() == "compiled" and _build() == "compiled"
    assert not native.exists()


_MUTATION = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 1 << 20), st.integers(1, 255)),
    st.tuples(st.just("truncate"), st.integers(0, 1 << 20), st.just(0)),
    st.tuples(st.just("extend"), st.binary(min_size=1, max_size=64), st.just(0)),
)


@settings(max_examples=25, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(mutation=_MUTATION)
def test_a_damaged_entry_is_compiled_again(native, mutation):
    """Any flipped byte, truncation or extension of a valid entry (object code or tag): compiled
    again with the exact results, and the entry put right."""
    if not native.exists():
        _build()
    (entry,) = native.glob("*.o")
    valid = entry.read_bytes()
    what, a, b = mutation
    if what == "flip":
        i = a % len(valid)
        damaged = valid[:i] + bytes([valid[i] ^ b]) + valid[i + 1:]
    elif what == "truncate":
        damaged = valid[: a % len(valid)]
    else:
        damaged = valid + a
    entry.write_bytes(damaged)
    assert _build() == "compiled"
    assert entry.read_bytes() == valid
