"""The agents a user trains, one file each in CleanRL's style (training/protocol.py says what an agent provides),
and the train / evaluate commands, run from a clone (``python -m training.<name>``); not in the wheel."""
