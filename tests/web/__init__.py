"""Browser tests of the twin. A package, so the package-scoped browser closes when they end
(without it pytest treats package scope as the session, and Playwright's loop outlives them)."""
