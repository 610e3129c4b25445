# ruff: noqa: E501 - template lines are HTML/Markdown, not Python
"""Templates of the calibration report: HTML (jinja2, autoescaped) and Markdown.

Prose written as Markdown (notes of the cross-validation and of the uncertainty estimate) is
rendered by markdown-it-py with raw HTML disabled, so no note can inject markup.
"""

from __future__ import annotations

import math

import jinja2
from markdown_it import MarkdownIt
from markupsafe import Markup, escape

from analysis.report.units import html_unit

__all__ = ["render_html", "render_markdown"]

_MD = MarkdownIt("commonmark", {"html": False, "linkify": False, "typographer": False})


def _parts(x, sig: int) -> tuple[str, int | None] | None:
    """(digits, power of ten or None) of ``x`` with ``sig`` significant digits."""
    if x is None or isinstance(x, bool):
        return None
    x = float(x)
    if not math.isfinite(x):
        return None
    if x == 0:
        return ("0", None)
    e = math.floor(math.log10(abs(x)))
    m = round(x / 10**e, sig - 1)
    if abs(m) >= 10:  # rounding carried into the next decade
        e, m = e + 1, m / 10
    if -3 <= e < 5:
        return (f"{x:.{max(sig - 1 - e, 0)}f}", None)
    return (f"{m:.{sig - 1}f}", e)


def num_html(x, sig: int = 4) -> Markup:
    p = _parts(x, sig)
    if p is None:
        return Markup("&ndash;")
    digits, e = p
    digits = digits.replace("-", "\u2212")
    if e is None:
        return Markup(escape(digits))
    return Markup(f"{escape(digits)}&#8239;&times;&#8239;10<sup>{e}</sup>")


def num_md(x, sig: int = 4) -> str:
    p = _parts(x, sig)
    if p is None:
        return "-"
    digits, e = p
    return digits if e is None else f"{digits}e{e}"


def signed(x, fmt: str = "+.2f") -> str:
    return "" if x is None else format(x, fmt).replace("-", "\u2212")


def md_inline(text: str) -> Markup:
    """Markdown prose (one paragraph) as HTML, raw HTML escaped."""
    return Markup(_MD.renderInline(str(text)))


def md_cell(text) -> str:
    """Text safe in a Markdown table cell."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _env(autoescape: bool) -> jinja2.Environment:
    env = jinja2.Environment(
        autoescape=autoescape,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters.update(
        num=num_html if autoescape else num_md,
        signed=signed,
        unit=(lambda u: Markup(html_unit(u))) if autoescape else (lambda u: u or ""),
        md=md_inline,
        cell=md_cell,
        g=lambda x: "" if x is None else format(float(x), "g"),
    )
    return env


HTML = r"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>Calibration report: {{ folder }}</title>
<style>
 body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; max-width: 1180px;
        margin: 1.5em auto; padding: 0 1em; color: #1b1f24; line-height: 1.45; }
 h1 { font-size: 1.7em; margin-bottom: 0.2em; }
 h2 { border-bottom: 2px solid #d0d7de; padding-bottom: 0.2em; margin-top: 1.8em; }
 table { border-collapse: collapse; margin: 0.6em 0 1em; font-size: 0.95em; }
 caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.3em; }
 th, td { border: 1px solid #d0d7de; padding: 0.3em 0.6em; vertical-align: top; }
 thead th { background: #f3f5f8; text-align: center; }
 td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
 td.name { font-family: ui-monospace, SFMono-Regular, Menlo, monospace; }
 .small { font-size: 0.85em; color: #57606a; }
 .badge { display: inline-block; padding: 0.05em 0.5em; border-radius: 0.8em; font-weight: 600;
          font-size: 0.9em; }
 .pass, .yes { background: #dafbe1; color: #116329; }
 .fail, .no { background: #ffebe9; color: #a40e26; }
 .held { background: #fff8c5; color: #7d4e00; }
 .at_bound { background: #ffebe9; color: #a40e26; }
 .fitted { background: #ddf4ff; color: #0a3069; }
 .summary { background: #f6f8fa; border: 1px solid #d0d7de; border-radius: 6px;
            padding: 0.6em 1em; }
 figure { margin: 1em 0 2em; }
 figure img { max-width: 100%; border: 1px solid #eaeef2; }
 figcaption { font-size: 0.9em; color: #57606a; }
 dt { font-weight: 600; }
 code { background: #f3f5f8; padding: 0 0.25em; border-radius: 3px; }
</style>
</head>
<body>
<h1>Calibration report</h1>
<p class="small">Folder <code>{{ folder }}</code>; all paths relative to this report's folder.</p>

<div class="summary">
{% if misfit %}
<p><span class="badge fail">MISFIT</span> <strong>The model misfits its data: the stated intervals are
not to be trusted.</strong> The model lacks something the structure does; <code>python -m analysis
diagnose</code> looks for what.</p>
<ul>{% for why in misfit %}<li>{{ why }}</li>{% endfor %}</ul>
{% elif adequate_rms %}
<p><span class="badge pass">adequate</span> The model fits its calibration data within
{{ adequate_rms|g }} &times; the noise: the stated intervals carry the noise, the misfit and the
uncertainty of the values the calibration holds.</p>
{% endif %}
<ul>
 <li>Measurement: <code>{{ measurement_file or "not recorded" }}</code>{% if model_source %};
     model: <code>{{ model_source }}</code>{% endif %}</li>
 <li>Calibration levels: {{ calibration_levels|map("g")|join(", ") }} N{% if validation_level is not none %};
     held out for validation: {{ validation_level|g }} N{% endif %}</li>
 <li>Fit: &chi;<sup>2</sup> per degree of freedom {{ chi2_per_dof|num(4) }}
     {%- if n_residuals %} over {{ n_residuals }} residuals{% endif %}
     {%- if weighting %} (weighting: {{ weighting }}){% endif %};
     Levenberg-Marquardt: {{ lm.nit }} iterations, {{ lm.message }}</li>
{% if validation %}
 <li>Validation at {{ validation.level|g }} N:
     <span class="badge {{ 'pass' if validation.passed else 'fail' }}">{{ 'PASS' if validation.passed else 'FAIL' }}</span>
     &chi;<sup>2</sup>/dof {{ validation.chi2_per_dof|num(3) }} (threshold {{ validation.threshold|num(3) }})</li>
{% endif %}
{% if reference and reference.coverage %}
 <li>Reference: {{ reference.coverage.inside }} of {{ reference.coverage.n }} reference values inside
     the stated 95&nbsp;% intervals{% if reference.coverage.outside %} (outside: {{ reference.coverage.outside|join(", ") }}){% endif %}
     {%- if reference.coverage.max_abs_z is not none %}; largest |z| {{ reference.coverage.max_abs_z|num(3) }}{% endif %}</li>
{% endif %}
</ul>
</div>

{% if reference %}
<p>Reference values: {{ reference.source or "reference file" }}
{%- if reference.file %} (<code>{{ reference.file }}</code>){% endif %}.
Error = (calibrated &minus; reference) / |reference|; z = (calibrated &minus; reference) / &sigma;,
with &sigma; the reported 1-sigma; &ldquo;inside&rdquo;: the reference lies in the stated 95&nbsp;% interval.</p>
{% endif %}

{% macro param_table(rows, caption, status=False, noise=False) %}
<table class="params">
<caption>{{ caption }}</caption>
<thead>
<tr>
 <th scope="col">parameter</th><th scope="col">unit</th>
{% if status %} <th scope="col">status</th>
{% endif %}
 <th scope="col">calibrated</th><th scope="col">1&sigma;</th>
{% if noise %} <th scope="col">1&sigma; noise only (FIM<sup>&minus;1</sup>)</th>
{% endif %}
 <th scope="col">95&nbsp;% interval</th>
{% if reference %} <th scope="col">reference</th><th scope="col">error [%]</th><th scope="col">z = error/&sigma;</th><th scope="col">reference inside 95&nbsp;%</th>
{% endif %}
</tr>
</thead>
<tbody>
{% for r in rows %}
<tr>
 <td class="name">{{ r.name }}</td><td>{{ r.unit|unit }}</td>
{% if status %} <td>{% if r.status %}<span class="badge {{ r.status }}">{{ r.status|replace("_", " ") }}</span>{% endif %}
  {%- if r.status_note %}<br><span class="small">{{ r.status_note|md }}</span>{% endif %}</td>
{% endif %}
 <td class="num">{{ r.value|num(5) }}</td>
 <td class="num">{{ r.std|num(2) }}{% if r.status == "held" %} <span class="small">(prior)</span>{% endif %}</td>
{% if noise %} <td class="num">{{ r.std_noise|num(2) }}</td>
{% endif %}
 <td class="num">[{{ r.low|num(4) }}, {{ r.high|num(4) }}]{% if r.interval_source and r.interval_source != "stated" %} <span class="small">({{ r.interval_source }})</span>{% endif %}</td>
{% if reference %}
{% if r.reference is not none %}
 <td class="num">{{ r.reference|num(5) }}</td><td class="num">{{ r.error_pct|signed("+.2f") }}</td><td class="num">{{ r.z|signed }}</td>
 <td>{% if r.inside is not none %}<span class="badge {{ 'yes' if r.inside else 'no' }}">{{ 'yes' if r.inside else 'no' }}</span>{% endif %}</td>
{% else %}
 <td colspan="4" class="small">{{ r.reference_note }}</td>
{% endif %}
{% endif %}
</tr>
{% endfor %}
</tbody>
</table>
{% endmacro %}

{% if linear %}
<h2>Linear calibration</h2>
<p class="small">From <code>{{ linear_file }}</code>.</p>
{{ param_table(linear, "Linear parameters (random test, damping equalization)", status=linear_has_status) }}
{% if linear_notes %}
<ul>
{% for n in linear_notes %} <li>{{ n|md }}</li>
{% endfor %}
</ul>
{% endif %}
{% if modal_damping %}
<table>
<caption>Identified modal damping ratios</caption>
<thead>
<tr><th scope="col">mode</th><th scope="col">&zeta; [%]</th>{% if reference %}<th scope="col">reference &zeta; [%]</th><th scope="col">error [%]</th>{% endif %}</tr>
</thead>
<tbody>
{% for m in modal_damping %}
<tr><td class="num">{{ m.mode }}</td><td class="num">{{ (100 * m.zeta)|num(3) }}</td>
{% if reference %}<td class="num">{{ (100 * m.reference) | num(3) if m.reference is not none else "" }}</td><td class="num">{{ m.error_pct|signed("+.2f") }}</td>{% endif %}</tr>
{% endfor %}
</tbody>
</table>
{% endif %}
{% endif %}

<h2>Nonlinear calibration</h2>
{{ param_table(nonlinear, "Contact parameters (stepped multi-sine, Levenberg-Marquardt)", noise=has_noise_std) }}
{% if uncertainty %}
<h3>How the uncertainty was estimated</h3>
{% if uncertainty.fields %}
<dl>
{% for k, v in uncertainty.fields %} <dt>{{ k }}</dt><dd>{{ v|md }}</dd>
{% endfor %}
</dl>
{% endif %}
{% if uncertainty.notes %}
<ul>
{% for n in uncertainty.notes %} <li>{{ n|md }}</li>
{% endfor %}
</ul>
{% endif %}
{% endif %}

{% if crossval %}
<h2>Cross-validation</h2>
<table>
<caption>{{ crossval.n_folds }}-fold cross-validation: spread of the fold estimates (CV) against the noise-only 1&sigma; (FIM<sup>&minus;1</sup>)</caption>
<thead>
<tr><th scope="col">parameter</th><th scope="col">unit</th><th scope="col">CV mean</th><th scope="col">CV 1&sigma;</th><th scope="col">FIM<sup>&minus;1</sup> 1&sigma;</th><th scope="col">ratio CV / FIM<sup>&minus;1</sup></th></tr>
</thead>
<tbody>
{% for r in crossval.rows %}
<tr><td class="name">{{ r.name }}</td><td>{{ r.unit|unit }}</td><td class="num">{{ r.mean|num(5) }}</td><td class="num">{{ r.std|num(2) }}</td><td class="num">{{ r.fim_std|num(2) }}</td><td class="num">{{ r.ratio|num(3) }}</td></tr>
{% endfor %}
</tbody>
</table>
{% if crossval.stuck %}
<p><span class="badge fail">warning</span> {{ crossval.stuck|length }} fold(s) could not leave the calibrated optimum
({{ crossval.stuck|join(", ") }}): the standard deviations understate the uncertainty.</p>
{% endif %}
{% if crossval.notes %}
<ul>
{% for n in crossval.notes %} <li>{{ n|md }}</li>
{% endfor %}
</ul>
{% endif %}
{% if crossval.folds %}
<table>
<caption>Per fold: misfit of the left-out data and each fold's share of the information</caption>
<thead>
<tr><th scope="col">fold left out</th><th scope="col">&chi;<sup>2</sup>/value at the optimum [&ndash;]</th><th scope="col">p (noise only)</th>
{% for n in crossval.names %}<th scope="col">share of {{ n }} [%]</th>{% endfor %}</tr>
</thead>
<tbody>
{% for f in crossval.folds %}
<tr><td>{{ f.fold }}</td><td class="num">{{ f.chi2|num(3) }}</td><td class="num">{{ f.p|num(2) }}</td>
{% for s in f.share %}<td class="num">{{ (100 * s)|num(2) if s is not none else "" }}</td>{% endfor %}</tr>
{% endfor %}
</tbody>
</table>
{% endif %}
{% endif %}

{% if validation %}
<h2>Validation</h2>
<p>Held-out level {{ validation.level|g }} N ({{ validation.n_steps }} steps, channels {{ validation.channels|join(", ") }}):
<span class="badge {{ 'pass' if validation.passed else 'fail' }}">{{ 'PASS' if validation.passed else 'FAIL' }}</span>
&chi;<sup>2</sup> per degree of freedom {{ validation.chi2_per_dof|num(3) }} (passes at most {{ validation.threshold|num(3) }});
{{ (100 * validation.within_2sigma)|num(3) if validation.within_2sigma is not none else "&ndash;"|safe }}&nbsp;% of the FRF values within 2&sigma;
(measurement and prediction uncertainty combined).</p>
{% endif %}

{% if figures %}
<h2>Figures</h2>
{% for f in figures %}
<figure>
<img src="{{ f.src }}" alt="{{ f.caption }}">
<figcaption>{{ f.caption }} <span class="small">(<code>{{ f.src }}</code>)</span></figcaption>
</figure>
{% endfor %}
{% endif %}

<h2>Inputs</h2>
<ul>
{% for p in inputs %} <li><code>{{ p }}</code></li>
{% endfor %}
{% if reference and reference.file %} <li><code>{{ reference.file }}</code> (reference values)</li>
{% endif %}
</ul>
</body>
</html>
"""

MARKDOWN = r"""# Calibration report

Folder `{{ folder }}`; all paths relative to this report's folder.
{% if misfit %}
**MISFIT: the model misfits its data; the stated intervals are not to be trusted.** `python -m analysis diagnose` looks for the missing effect.
{% for why in misfit %}
- {{ why }}
{% endfor %}
{% elif adequate_rms %}
The model fits its calibration data within {{ adequate_rms|g }} x the noise: the stated intervals carry the noise, the misfit and the uncertainty of the held values.
{% endif %}

- Measurement: `{{ measurement_file or "not recorded" }}`
- Calibration levels: {{ calibration_levels|map("g")|join(", ") }} N{% if validation_level is not none %}; held out: {{ validation_level|g }} N{% endif %}

- Fit: chi2 per degree of freedom {{ chi2_per_dof|num(4) }}; LM {{ lm.nit }} iterations, {{ lm.message }}
{% if validation %}
- Validation at {{ validation.level|g }} N: **{{ 'PASS' if validation.passed else 'FAIL' }}**, chi2/dof {{ validation.chi2_per_dof|num(3) }} (threshold {{ validation.threshold|num(3) }})
{% endif %}
{% if reference and reference.coverage %}
- Reference ({{ reference.source }}): {{ reference.coverage.inside }} of {{ reference.coverage.n }} values inside the stated 95 % intervals
{% endif %}

{% macro param_table(rows, status=False, noise=False) %}
| parameter | unit |{% if status %} status |{% endif %} calibrated | 1 sigma |{% if noise %} 1 sigma noise only |{% endif %} 95 % interval |{% if reference %} reference | error [%] | z | inside |{% endif %}

|---|---|{% if status %}---|{% endif %}---:|---:|{% if noise %}---:|{% endif %}---|{% if reference %}---:|---:|---:|---|{% endif %}

{% for r in rows %}
| {{ r.name }} | {{ r.unit }} |{% if status %} {{ r.status|replace("_", " ") }}{% if r.status_note %} ({{ r.status_note|cell }}){% endif %} |{% endif %} {{ r.value|num(5) }} | {{ r.std|num(2) }} |{% if noise %} {{ r.std_noise|num(2) }} |{% endif %} [{{ r.low|num(4) }}, {{ r.high|num(4) }}] |{% if reference %}{% if r.reference is not none %} {{ r.reference|num(5) }} | {{ r.error_pct|signed("+.2f") }} | {{ r.z|signed }} | {{ "" if r.inside is none else ("yes" if r.inside else "no") }} |{% else %} | | | {{ r.reference_note|cell }} |{% endif %}{% endif %}

{% endfor %}
{% endmacro %}
{% if linear %}
## Linear calibration

{{ param_table(linear, status=linear_has_status) }}
{% endif %}
## Nonlinear calibration

{{ param_table(nonlinear, noise=has_noise_std) }}
{% if uncertainty %}
{% for k, v in uncertainty.fields %}
- {{ k }}: {{ v }}
{% endfor %}
{% for n in uncertainty.notes %}
- {{ n }}
{% endfor %}
{% endif %}
{% if crossval %}

## Cross-validation

| parameter | unit | CV mean | CV 1 sigma | FIM^-1 1 sigma | ratio |
|---|---|---:|---:|---:|---:|
{% for r in crossval.rows %}
| {{ r.name }} | {{ r.unit }} | {{ r.mean|num(5) }} | {{ r.std|num(2) }} | {{ r.fim_std|num(2) }} | {{ r.ratio|num(3) }} |
{% endfor %}

{% for n in crossval.notes %}
- {{ n }}
{% endfor %}
{% endif %}
{% if figures %}

## Figures

{% for f in figures %}
![{{ f.caption }}]({{ f.src }})

{% endfor %}
{% endif %}
"""

_HTML_ENV = _env(autoescape=True)
_MD_ENV = _env(autoescape=False)


def render_html(ctx: dict) -> str:
    return _HTML_ENV.from_string(HTML).render(**ctx)


def render_markdown(ctx: dict) -> str:
    return _MD_ENV.from_string(MARKDOWN).render(**ctx)
