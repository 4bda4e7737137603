"""The interactive window: manual driving, recording and autonomous mode, on top of sim, data
and udacity."""
