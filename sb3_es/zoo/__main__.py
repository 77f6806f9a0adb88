"""``python -m sb3_es.zoo COMMAND [rl-zoo arguments]``."""

from sb3_es.zoo.commands import main

main()
