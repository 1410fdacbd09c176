import a_module_that_does_not_exist  # noqa: F401  (a third-party plugin with a missing dependency)
