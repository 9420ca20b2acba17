"""Writing results: the text, files and figures of a fit (``_fit``; its figures drawn by
``_plot``), a posterior (``_mcmc``), a diagnosis (``_diagnosis``), a model comparison
(``_compare``) and a decay posterior (``_decays``). The result objects hold results only
(their ``to_dict()`` is the plain-data view); what a person reads or a file holds is made
here, and the commands (``_commands``, ``_cli``) call it. Public through
:mod:`pamid.report`. matplotlib and ArviZ load only when a figure is drawn (``_plot`` is
imported inside the functions that draw), so that writing JSON stays cheap."""
