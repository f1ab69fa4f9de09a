"""``python -m hifumotion`` runs the command line."""

from hifumotion.cli import main

main()
