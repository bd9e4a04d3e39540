"""Baseline reflectance models users expect beside the cloth models: a yardstick for what the yarn structure
adds.  Modules: lambert (:class:`LambertModel`, ``kind: lambert``), oren_nayar (:class:`OrenNayarModel`,
``kind: oren-nayar``).  Each is one :class:`clothlab.models.base.Model` and one registry line."""
