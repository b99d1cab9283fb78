#!/bin/bash
# Underrun with a planner that falls behind but lives on: it is frozen mid-path, then continued,
# notices the module's stop point by itself, re-plans from there; the resume command runs it to the
# end (see underrun_test.sh).
exec bash "$(dirname "$0")/underrun_test.sh" freeze
