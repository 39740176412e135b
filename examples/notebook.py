# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # flexopt in a notebook
#
# A cross-spring pivot from the built-in templates: its stroke-dependent first parasitic frequency, the
# curve as a table and a figure, the exact-constraint diagnosis and the mode shapes at 30 degrees. Run it with
# `jupytext --to ipynb examples/notebook.py` and open the notebook, or execute it as the tests do.

# %%
# %matplotlib inline
import flexopt

pivot = flexopt.template("cross-spring-pivot", thickness="0.3 mm", points=19)
curve = flexopt.curve(pivot, method="hermite", tolerance=0.01)
curve  # the rich form: summary, warnings, a short table

# %%
df = curve.to_dataframe()
df[["parasitic_hz", "drive_reaction_Nm"]].head()

# %%
fig = curve.plot()
fig

# %%
diagnosis = flexopt.diagnose(pivot)
print(diagnosis.report())

# %%
shapes = flexopt.modes(pivot, at_stroke=30)
[(m.hz, m.label) for m in shapes.modes][:4]
