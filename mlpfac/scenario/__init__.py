"""A scenario: a TOML file parsed into plain, validated data (:mod:`mlpfac.scenario.parse`), the reference it names, the provenance that makes a re-run exact."""
