"""`--for hub`: Parquet shards `OUT/data/<config>/<split>-*.parquet` that `datasets`
loads and the Hugging Face Hub shows (docs/guide/hub.md), written by
blurset.export_hub, whose `run` plans and writes them and whose `--shard-size` only this
target reads.
"""

from __future__ import annotations

from blurset import export_hub
from blurset.export_rules import OwnOutput, Target

TARGET = Target(
    name=export_hub.TARGET,
    help="Parquet shards OUT/data/<config>/<split>-*.parquet that `datasets` loads and the "
    "Hugging Face Hub shows (one config per level and gain)",
    docs="guide/hub.md",
    output=OwnOutput(
        run=export_hub.run,
        add_arguments=export_hub.add_arguments,
        options=("shard_size",),
        does="writes shards",
    ),
)
