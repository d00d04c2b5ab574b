"""The afternoon conducted run by run (``rapt-plan next``): it reads what the day's runs showed, with the
review's tools, and places the next run, with the plan's, so it sits above both stages."""
