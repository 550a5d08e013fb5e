"""The LLFF-N noise model, public (DESIGN §5): `model`. The command `blurset noise` is
`blurset.commands.noise`."""
