#!/bin/bash
# Underrun in real LinuxCNC: the planner is unloaded mid-path; a second planner re-plans from the
# module's stop point and the resume command runs it to the end (see underrun_test.sh).
exec bash "$(dirname "$0")/underrun_test.sh" unload
