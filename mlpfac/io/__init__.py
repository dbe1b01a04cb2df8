"""What mlpfac does with the world outside it: files and folders written whole (:mod:`~mlpfac.io.files`),
the paths a user names for it to write, checked before anything runs (:mod:`~mlpfac.io.targets`),
SIGINT and SIGTERM held back while they are written (:mod:`~mlpfac.io.interrupts`), and how the
command line ends when something other than bad input stops it (:mod:`~mlpfac.io.exits`)."""
