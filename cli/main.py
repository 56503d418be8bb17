
from __future__ import annotations

import click



@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main() -> None:


main.add_command(body)
main.add_command(import_amass)
main.add_command(export_amass)
