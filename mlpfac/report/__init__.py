"""The results pages' tables written from the data kept beside them (:mod:`~mlpfac.report.results`,
``mlpfac report``), and that data run again bit for bit (:mod:`~mlpfac.report.verify`,
``mlpfac report --verify N``)."""
