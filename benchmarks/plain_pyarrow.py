"""Plain pyarrow: read a Parquet file in record batches, append one float64 column, write it with
zstd. The Parquet I/O a file-to-file prediction cannot avoid, and the yardstick of the
prediction benchmarks (``benchmarks/run.py``'s ``plain_pyarrow_s``).

    python benchmarks/plain_pyarrow.py SRC DST

Run this way it is a program of its own, started as a ``fricli`` command is: its interpreter
start-up, imports and first allocations count, as theirs do (``plain_pyarrow_process_s``). Called
again and again in one warm process (``plain_pyarrow_s``) the same work is faster: pyarrow's
memory pool and the pages it maps are reused."""

from __future__ import annotations

import sys
from typing import Callable

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq


def copy_with_column(src: str, dst: str, batch_rows: int = 1 << 20,
                     options: Callable[[pa.Schema], dict] | None = None) -> None:
    """Read ``src`` in batches of ``batch_rows``, append ``tau_f_pred`` = qd / 2, write ``dst``
    (``options(schema)``: the writer's options; default zstd)."""
    writer = None
    for batch in pq.ParquetFile(src).iter_batches(batch_size=batch_rows):
        table = pa.Table.from_batches([batch])
        table = table.append_column("tau_f_pred", pa.array(np.asarray(table.column("qd")) * 0.5))
        if writer is None:
            writer = pq.ParquetWriter(dst, table.schema,
                                      **(options(table.schema) if options else {"compression": "zstd"}))
        writer.write_table(table)
    writer.close()


if __name__ == "__main__":
    copy_with_column(sys.argv[1], sys.argv[2])
