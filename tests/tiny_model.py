"""The tiny network the model, inference and training tests share (CPU, well under a second).

Import it as ``from tiny_model import TINY_MODEL`` (tests/ is on the test path) or take the
``tiny_config`` / ``tiny_network`` fixtures of conftest.py.
"""

#: :class:`specgen_addon.model.Config` fields of a network small enough for unit tests.
TINY_MODEL = dict(image_size=32, encoder_channels=(8, 16), latent_dim=32, decoder_seed_hw=(4, 4),
                  decoder_channels=(16, 8), head_channels=8, res_theta_h=8, res_theta_d=8, res_phi_d=12,
                  res_lambda=6, feature_dim=16, aff_map_hw=(4, 4), mlp_hidden=(16, 16))
