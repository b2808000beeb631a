"""The kinematics stage: scaling and inverse kinematics (stage.py runs it in order; the README's
"How scaling and inverse kinematics work")."""
