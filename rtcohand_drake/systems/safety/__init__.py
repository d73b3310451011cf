"""The safety layer between the command filter and the differential IK.

`supervisor` is the Drake system (watchdog, pause, sensitivity, limits);
`rules` holds the zone rules, each one function and one flag, and the table
the run log's event names come from; `config` holds its scenario keys.
"""
