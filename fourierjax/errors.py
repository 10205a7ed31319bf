"""Exception types a user can meet: one per kind of mistake, each naming what is wrong."""


class FourierJaxError(Exception):
    """Base class of every error fourierjax raises on purpose."""


class UserError(FourierJaxError, ValueError):
    """A mistake in what the user asked for (a bad argument, an unknown name, a missing file)."""
