"""The controller blocks: the laws (35) and Kanayama's, the oracle told each change, users' controllers (plug-ins), the shipped names; the adaptive scheme in :mod:`mlpfac.control.adaptive`."""
