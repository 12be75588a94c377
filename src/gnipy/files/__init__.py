"""What gnipy owns on disk: safe destinations, atomic writes, output locks, owned directories,
checksums (a module each: :mod:`~gnipy.files.destinations`, :mod:`~gnipy.files.atomic`,
:mod:`~gnipy.files.locks`, :mod:`~gnipy.files.owned`, :mod:`~gnipy.files.checksums`).

Every file or directory gnipy writes goes through this module, so the rules hold everywhere
(`gni run`, `gni sweep`, `gni convergence`, `gni reproduce`, :func:`gnipy.write_netcdf`,
:func:`gnipy.simulate_to_file`, :func:`gnipy.run_sweep`):

**Destinations** (:func:`check_destination`). gnipy writes a regular file or a directory at a
path only if nothing is there, or a regular file (resp. a directory that gnipy created, see
below) is there and the caller allowed replacing it (`overwrite=True`, `--overwrite`). It never
writes through or replaces a symbolic link, a device, a FIFO or a socket, whatever the flags.

**Atomic writes** (:func:`atomic_write`, :func:`atomic_write_text`, :func:`atomic_savefig`). The
data go to a temporary file beside the destination, are flushed to disk, and the temporary file
then replaces the destination with `os.replace` (atomic on POSIX within one file system). A reader
sees the old file or the new one, never half of one; on any failure (a full disk, Ctrl-C) the
temporary file is removed and the old file is left as it was. Every failure to write, including
the netCDF library's `RuntimeError: NetCDF: HDF error` on a full disk, becomes an
:class:`OutputError` that names the path.

**Temporaries** are named `.NAME.gnipy-PID-HEX.tmp` (or `.partial` for directories): the
process id lets the next run remove the temporaries of a process that died (SIGKILL, power loss)
without touching those of a run still going (:func:`clean_stale_temporaries`, which every atomic
write, streamed run and sweep calls for its destination before it writes).

**One writer per output** (:class:`output_lock`). A run holds the lock of its output (a file or a
store) from its first check to its last write: a lock file `.NAME.gnipy-lock` beside the output,
locked with `flock` and holding the owner's process id. A second process asking for the same
output is refused at once (:class:`OutputBusy`, naming the owner's PID) instead of deleting the
first one's checkpoints or racing it to the rename. The kernel releases the lock when its process
dies, however it dies, so a lock file left by a killed run is stale by construction: the next
writer takes it over and removes it when done.

**Owned directories** (:func:`make_owned_dir`, :func:`remove_owned_dir`). A working directory
gnipy creates (the checkpoint parts of a streamed run, a sweep store) holds a marker file
:data:`MARKER`; gnipy removes or replaces a directory only when the marker is there, and even then
deletes only the files it writes itself: a file someone else put there is left, with the
directory.

**Checksums** (:class:`DataChecksum`). A checksum of named arrays (SHA-256 of each array's
dtype, shape and C-order bytes), computed in pieces along the first axis so long runs can be
summed as they stream; checkpoint parts, sweep chunks and result files carry one, and a resume or
`gni verify` recomputes it.
"""

from ..errors import OutputBusy, OutputError
from .atomic import (
    as_output_error,
    atomic_savefig,
    atomic_write,
    atomic_write_text,
    clean_stale_temporaries,
    temporary_name,
)
from .checksums import DataChecksum, array_checksum, as_stored
from .destinations import check_destination, check_directory_destination, format_bytes, free_bytes
from .locks import lock_path, output_lock
from .owned import MARKER, is_owned_dir, make_owned_dir, remove_owned_dir

__all__ = [
    "OutputError",
    "OutputBusy",
    "MARKER",
    "check_destination",
    "check_directory_destination",
    "atomic_write",
    "atomic_write_text",
    "atomic_savefig",
    "temporary_name",
    "clean_stale_temporaries",
    "output_lock",
    "lock_path",
    "make_owned_dir",
    "is_owned_dir",
    "remove_owned_dir",
    "DataChecksum",
    "as_stored",
    "array_checksum",
    "as_output_error",
    "format_bytes",
    "free_bytes",
]
