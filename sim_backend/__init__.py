"""The simulated rig: a DAQ backend backed by a truth structure, for every test and demo.

``rig.backends.open_backend("sim", truth="reference", ...)`` opens
:class:`sim_backend.daq.SimulatedDaq`, which satisfies the rig's DAQ backend protocol by shape
(this package does not import ``rig``). Data flow, one module each::

    truth.py        truth structures (model file + [truth] table), truths/*.toml
    shaker.py       shaker and stinger constants, frequency-domain coupling terms
    coupled.py      structure + shaker receptance blocks with the voltage as an input
    statespace.py   the same rig in diagonalised state-space form, exact discretisation
    rig_model.py    the coupled balance problem and sensor outputs for a sensor set
    integrator.py   sample-by-sample time integration with the nonlinear elements
    simulation.py   the timeline: steady states, transients, amplifier protection
    drive.py        the DAQ output program (regenerated waveform, cross-fades)
    sensors.py      sensor noise, ADC range and quantisation, fault switches
    checks.py       checks of drive waveforms and channel configurations
    daq.py          SimulatedDaq, the backend
    amplifier.py, serial_amplifier.py   the power amplifier and its serial front panel
    sizing.py       how far a hidden effect shows above the noise in the paper's test
"""
