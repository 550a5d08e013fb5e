"""COLMAP on one scene: features and matching once, mapping on demand."""

from __future__ import annotations

from pathlib import Path

from blurset.exceptions import ConfigError

# Set by `--verbose` to let COLMAP's own log through.
VERBOSE = False


class _Colmap:
    """COLMAP on one scene: SIFT + exhaustive matching once, with the shared pinhole
    intrinsics held fixed; incremental mapping on demand (`map(seed)`), so a second
    opinion costs a mapping, not a new database."""

    def __init__(self, image_dir: Path, names: list[str], intrinsics, workdir: Path):
        import pycolmap

        self.pycolmap, self.image_dir, self.workdir = pycolmap, image_dir, workdir
        self.db_path = workdir / COLMAP_DATABASE
        _refuse_used_workdir(workdir)
        w, h, f = intrinsics
        with self._quiet():
            pycolmap.set_random_seed(0)
            reader = pycolmap.ImageReaderOptions()
            reader.camera_model = "PINHOLE"
            reader.camera_params = f"{f!r},{f!r},{w / 2!r},{h / 2!r}"
            extraction = pycolmap.FeatureExtractionOptions()
            extraction.use_gpu = False
            pycolmap.extract_features(
                self.db_path,
                image_dir,
                image_names=names,
                camera_mode=pycolmap.CameraMode.SINGLE,
                reader_options=reader,
                extraction_options=extraction,
                device=pycolmap.Device.cpu,
            )
            matching = pycolmap.FeatureMatchingOptions()
            matching.use_gpu = False
            pycolmap.match_exhaustive(
                self.db_path, matching_options=matching, device=pycolmap.Device.cpu
            )
        self.features: dict[str, int] = {}
        with pycolmap.Database.open(self.db_path) as db:
            for image in db.read_all_images():
                self.features[image.name] = int(db.num_keypoints_for_image(image.image_id))

    def _quiet(self):
        """COLMAP logs every step at INFO; the report says what matters."""
        import contextlib

        pycolmap = self.pycolmap

        @contextlib.contextmanager
        def quiet():
            level = pycolmap.logging.minloglevel
            if not VERBOSE:
                pycolmap.logging.minloglevel = 3
            try:
                yield
            finally:
                pycolmap.logging.minloglevel = level

        return quiet()

    def map(self, seed: int = 0):
        """The largest reconstruction of incremental mapping with `seed`, or None."""
        pycolmap = self.pycolmap
        sparse = self.workdir / ("sparse" if seed == 0 else f"sparse_seed{seed}")
        sparse.mkdir(parents=True, exist_ok=True)
        opts = pycolmap.IncrementalPipelineOptions()
        opts.random_seed = seed
        opts.multiple_models = False
        # The intrinsics are under test together with the poses: never refine them.
        opts.ba_refine_focal_length = False
        opts.ba_refine_principal_point = False
        opts.ba_refine_extra_params = False
        opts.mapper.abs_pose_refine_focal_length = False
        opts.mapper.abs_pose_refine_extra_params = False
        opts.mapper.random_seed = seed
        opts.triangulation.random_seed = seed
        with self._quiet():
            if seed:
                pycolmap.set_random_seed(seed)
            recs = pycolmap.incremental_mapping(self.db_path, self.image_dir, sparse, options=opts)
        return max(recs.values(), key=lambda r: r.num_reg_images(), default=None)


COLMAP_DATABASE = "database.db"


def _refuse_used_workdir(workdir: Path) -> None:
    """ConfigError naming --workdir when `workdir` already holds a COLMAP database or
    sparse model: check-poses writes its own there and never deletes one (it may be the
    user's own COLMAP workspace, or a model they kept)."""
    if not workdir.is_dir():
        return
    used = sorted(
        p.name
        for p in workdir.iterdir()
        if p.name == COLMAP_DATABASE or (p.is_dir() and p.name.startswith("sparse"))
    )
    if used:
        raise ConfigError(
            f"--workdir {workdir}: already holds {', '.join(used)} (check-poses writes a new "
            "COLMAP database and model there and deletes none): name a new folder, or "
            "remove them yourself"
        )
