"""Hidden-effect tests on the walk (:mod:`tests.diagnose.hidden`; one module per trial so that
the test workers run the trials side by side)."""

from tests.diagnose.hidden import trial_tests

base, test_hidden_cause_is_named_and_recovered, test_shift_of_one_plate_or_of_every_plate = trial_tests("walk")
