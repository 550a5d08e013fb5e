"""blurset's commands, one module or package per subcommand of `blurset` (`cli.py` at the
package's top dispatches to them): `build/`, `noise/`, `export/`, `check_poses/`,
`tradeoff/`, `preview`, `stats`, `card`, `verify`. A command imports services and public
faces; neither imports a command (`tests/test_package_roles.py`)."""
