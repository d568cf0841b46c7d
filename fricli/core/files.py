"""Reading an input file whole, with its failures as one user-facing error."""

from __future__ import annotations


def read_bytes(path: str, error: type[Exception], missing: str, folder: str) -> bytes:
    """The bytes of ``path``; ``error`` (a FricliError) with "no such ``missing``", "is a folder,
    not a ``folder``" or the system's reason when it cannot be read."""
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except FileNotFoundError:
        raise error(f"{path}: no such {missing}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {folder}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
