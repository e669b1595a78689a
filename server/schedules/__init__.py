"""Schedules: one-shot, interval and cron (with a time zone); each due time starts exactly one run."""
