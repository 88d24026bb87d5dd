"""What the simulator is calibrated and checked against:

- :mod:`sim.calibration.presets`: the tissue presets (moduli, strain limit, needle forces) and
  their sources;
- :mod:`sim.calibration.indentation`: the indentation experiments (force-depth curves, the needle
  pressed on the paper's 10 mm test cube, load cycles) that the presets are fitted to and tested on;
- :mod:`sim.calibration.scenarios`: named meshes with their supports and contact candidates (the
  paper's Table 2 slabs, the arteries) for the benchmarks.
"""
