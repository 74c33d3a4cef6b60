"""Config -> CompiledGame: the KKT system with exact derivatives, condensed and sparse."""
