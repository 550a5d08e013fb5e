"""`blurset noise`, LLFF-N style noise (DESIGN §5): `cli` (the command), `scene` (one LLFF
scene), `build` (every level of a build), `params` (gains, the σ table, noise.json). The
noise model itself is public: `blurset.noise.model`."""
