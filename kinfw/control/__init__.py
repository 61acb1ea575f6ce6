"""Using a calibration: fixating points with a head's cameras (:mod:`.gaze`) and reaching
poses or points with any frame (:mod:`.reach`), both by bounded Gauss-Newton on
Pinocchio's exact kinematics (:mod:`.solver`)."""
