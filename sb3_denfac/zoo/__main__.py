"""``python -m sb3_denfac.zoo``: the same as the ``sb3-denfac-zoo`` command."""

from sb3_denfac.zoo.usage import main

main()
