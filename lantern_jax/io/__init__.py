"""Layer 2, files on disk: atomic writes and staged result folders
(:mod:`~lantern_jax.io.files`), configuration files (:mod:`~lantern_jax.io.config_file`) and
compiled programs kept between runs (:mod:`~lantern_jax.io.program_store`)."""
