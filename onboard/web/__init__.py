"""The pre-flight check page: a small web process that reads the recorder's status snapshot.

It never touches the serial port or the journal, so a fault here cannot stop recording.
"""
