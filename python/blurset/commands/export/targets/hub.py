"""`--for hub`: Parquet shards `OUT/data/<config>/<split>-*.parquet` that `datasets`
loads and the Hugging Face Hub shows (docs/guide/hub.md), written by
blurset.commands.export.hub, whose `run` plans and writes them and whose `--shard-size` only this
target reads.
"""

from __future__ import annotations

from blurset.commands.export import hub as export_hub
from blurset.commands.export.rules import OwnOutput, Target
from blurset.services import hub_format

TARGET = Target(
    name=hub_format.TARGET,
    help="Parquet shards OUT/data/<config>/<split>-*.parquet that `datasets` loads and the "
    "Hugging Face Hub shows (one config per level and gain)",
    docs="guide/hub.md",
    output=OwnOutput(
        run=export_hub.run,
        add_arguments=export_hub.add_arguments,
        options=("shard_size",),
        does="writes shards",
        replaced=export_hub.drop_card,
    ),
)
