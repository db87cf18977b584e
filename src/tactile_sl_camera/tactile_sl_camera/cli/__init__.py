"""`tactile-sl` subcommands that belong to the camera package (registered by tactile_sl_decoder.cli)."""
