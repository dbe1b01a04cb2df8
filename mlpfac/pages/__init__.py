"""The reference pages written from the code: ``docs/api.md`` (:mod:`~mlpfac.pages.doc_pages`) and
``docs/scenario-file.md`` (:mod:`~mlpfac.pages.scenario_doc`); ``python -m mlpfac.pages docs [--check]``."""
