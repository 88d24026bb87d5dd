"""The sources the needle hand's metrics cite (shown with each metric in the registry table)."""

MOTION_REF = "Oropesa et al. 2013, Surg Endosc 27:1029 (motion analysis review)"
SMOOTH_REF = "Balasubramanian et al. 2015, J NeuroEng Rehabil 12:112"
PAPER_REF = "the vascsim source paper (haptic simulator for suturing in vascular surgery), section 10"
