"""`blurset export`: `cli` (the command and the flow every scene-folder target shares),
`rules` (what every target shares), `scene` (an LLFF scene folder's files), `hub` (Hub
shards), `targets/` (the registry of `--for`, one module per target)."""
