"""The autonomous run: the persisted state machine of one mission from a landing base and back."""
