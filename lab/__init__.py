"""The lab's infrastructure under training/, studies/ and devtools/ (not in the wheel): report commands
(common.report_command), the reports' provenance (provenance), success-rate intervals (stats) and resumable jobs
(jobs). It imports penny_env and nothing else of the repository."""
