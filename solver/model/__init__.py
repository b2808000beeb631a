"""OpenSim models (.osim) as pinocchio models: parsing, OpenSim's functions and joint coupling,
scaling, writing back (the README's "How the model conversion works")."""
