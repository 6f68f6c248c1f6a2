"""Arrays that carry their column names, units and time: what the Python API hands out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class NamedArray:
    """A frames × columns array with the name and unit of every column and the frame times.

    ``a["knee_flexion_r"]`` is one column (a 1-D array over frames); ``a.values`` or
    ``np.asarray(a)`` the whole array (``a.shape``: frames × columns); ``a.to_dataframe()`` a
    pandas DataFrame indexed by time (pandas is optional).

    Attributes
    ----------
    values : ndarray
        n_frames × n_columns, each column in its own unit.
    names : tuple of str
        The columns' names (n_columns).
    units : tuple of str
        Each column's unit (n_columns), e.g. 'rad', 'N·m', 'deg'.
    time : ndarray
        The frames' times (n_frames, s) on the trial file's clock (its first frame's time: a
        C3D's first frame, a TRC's first Time), as its events and every export count them.
    """

    values: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    time: np.ndarray

    def __post_init__(self) -> None:
        if self.values.ndim != 2 or self.values.shape[1] != len(self.names) or \
                len(self.units) != len(self.names) or len(self.time) != len(self.values):
            raise ValueError(f"NamedArray: values {self.values.shape} do not match "
                             f"{len(self.names)} names, {len(self.units)} units and "
                             f"{len(self.time)} times")

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"{name!r}: expected one of {', '.join(self.names)}") from None

    def __len__(self) -> int:
        return len(self.values)

    def __array__(self, dtype: np.dtype | None = None, copy: bool | None = None) -> np.ndarray:
        """The values to numpy (``np.asarray(a)``, ``np.mean(a, axis=0)``), with numpy 2's
        ``copy`` contract: None copies only to change the dtype, True always, False never (a
        ValueError where the dtype asks for one)."""
        values = np.asarray(self.values)
        if dtype is None or np.dtype(dtype) == values.dtype:
            return values.copy() if copy else values
        if copy is False:
            raise ValueError(f"NamedArray: {values.dtype} values cannot become {np.dtype(dtype)} "
                             "without a copy")
        return values.astype(dtype)

    @property
    def shape(self) -> tuple[int, ...]:
        """(frames, columns)."""
        return self.values.shape

    @property
    def dtype(self) -> np.dtype:
        return self.values.dtype

    def __repr__(self) -> str:
        units = sorted(set(self.units))
        return (f"NamedArray({len(self.time)} frames × {len(self.names)}: "
                f"{', '.join(self.names[:4])}{' …' if len(self.names) > 4 else ''}; "
                f"{', '.join(units)})")

    @property
    def unit(self) -> dict[str, str]:
        """Column name → unit."""
        return dict(zip(self.names, self.units, strict=True))

    def to_dataframe(self):
        """A pandas DataFrame (index: time in s; columns 'name [unit]').

        Returns
        -------
        pandas.DataFrame
            n_frames × n_columns, the values in each column's unit.

        Raises
        ------
        ImportError
            pandas is not installed (the ``pandas`` extra).
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("to_dataframe needs pandas: pip install 'fccgrb-cli[pandas]'") \
                from None
        columns = [f"{n} [{u}]" for n, u in zip(self.names, self.units, strict=True)]
        return pd.DataFrame(self.values, index=pd.Index(self.time, name="trial time [s]"),
                            columns=columns)
