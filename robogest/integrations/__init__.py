"""Adapters to voice-agent frameworks (each an optional extra): :mod:`robogest.integrations.pipecat`.

Nothing is imported here, so the extras stay optional: import the adapter's own module.
"""
