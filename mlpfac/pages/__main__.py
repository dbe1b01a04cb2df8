"""``python -m mlpfac.pages DOCS [--check]``: write the reference pages, or check them."""

import sys

from mlpfac.pages.doc_pages import main

sys.exit(main(sys.argv[1:]))
