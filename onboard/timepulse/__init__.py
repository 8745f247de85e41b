"""Camera TimePulse settings (CFG-TP5 / legacy CFG-TP fields), pulse/flash pairing and the event log records.

Pure: field values and records only; serialising to UBX frames is `onboard.receiver.profiles`' job, appending
and fsyncing `events.jsonl` is `onboard.logger.events`'.
"""
